"""The options ``lubjax`` and ``lubjax-fit`` share mean the same in both: one name, type,
default, choices and help (lubjax._cli_options)."""

import pytest

import lubjax
import lubjax._cli as lcli
import lubjax._cli_scenes as lscenes
from fitting import _cli as fcli
from fitting._model import FIT_SETTINGS
from lubjax._cli_options import layer_poisson
from lubjax._files import UsageError

SUBSTRATE = ("--substrate", "--thickness", "--layer-base", "--layer-poisson")
SAME_EVERYWHERE = SUBSTRATE + ("--order", "--no-cache", "--debug")


def _actions(parser):
    return {opt: a for a in parser._actions for opt in a.option_strings}


def _lubjax_commands():
    sub = next(a for a in lcli._parser()._actions if a.dest == "command")
    return sub.choices


@pytest.mark.parametrize("command", ["relax", "creep", "bounce"])
def test_shared_options_are_the_same_in_both_parsers(command):
    ours, fits = _actions(_lubjax_commands()[command]), _actions(fcli.build_parser())
    for opt in SAME_EVERYWHERE:
        a, b = ours[opt], fits[opt]
        assert (a.dest, a.type, a.default, a.choices, a.help, type(a)) == (
            b.dest, b.type, b.default, b.choices, b.help, type(b)), opt
    # --rtol: the same option; its default is each command's Settings (the fit's is looser)
    a, b = ours["--rtol"], fits["--rtol"]
    assert (a.type, a.default) == (b.type, b.default) and a.default is None
    assert f"default {lubjax.Settings().rtol:g})" in a.help
    assert f"default {FIT_SETTINGS.rtol:g})" in b.help
    assert a.help.replace(f"{lubjax.Settings().rtol:g}", "X") == b.help.replace(
        f"{FIT_SETTINGS.rtol:g}", "X")


def test_layer_defaults_mean_the_same():
    """Not given, the layer is bonded and takes the solid's --poisson, else 0.5, in both."""
    for argv, parse in [(["relax", "--substrate", "layer"], lcli._parser().parse_args),
                        (["t.csv", "--substrate", "layer"], fcli.build_parser().parse_args)]:
        args = parse(argv)
        assert args.layer_base is None and args.layer_poisson is None
        assert layer_poisson(args) == 0.5
        args.poisson = 0.3
        assert layer_poisson(args) == 0.3
        args.layer_poisson = 0.7
        with pytest.raises(UsageError, match=r"--layer-poisson must be in \(-1, 0.5\], got 0.7"):
            layer_poisson(args)


@pytest.mark.parametrize("argv", [["--layer-poisson", "0.4"], ["--layer-base", "frictionless"]])
def test_layer_options_without_a_layer_are_refused_by_both(argv, capsys):
    si = ["--E-star", "3.92e6", "--viscosity", "100", "--radius", "2e-3", "--speed", "1e-4",
          "--indent", "140e-6", "--gap", "140e-6"]
    assert lcli.main(["relax", *si, *argv]) == 2
    assert f"{argv[0]}: only with --substrate layer" in capsys.readouterr().err
    assert fcli.main(["trace.csv", *argv])  # refused before reading it == 2
    assert f"{argv[0]}: only with --substrate layer" in capsys.readouterr().err


@pytest.mark.parametrize("command", ["creep", "bounce"])
def test_the_drives_take_the_accuracy_options(command):
    args = lcli._parser().parse_args([command, "--rtol", "1e-5", "--order", "3",
                                      "--max-steps", "500"])
    settings = lscenes.settings_of(args)
    assert (settings.rtol, settings.order, settings.max_steps) == (1e-5, 3, 500)
    assert lscenes.settings_of(lcli._parser().parse_args([command])) == lubjax.Settings()

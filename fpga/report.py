"""``OUT/report.json`` and ``OUT/report.md`` of ``bayesmachine synth``: resources, fmax, critical
path, machines that fit, and the throughput those imply (the keys are listed in docs/fpga.md). One
shape for both tops: the stereo top (``top = "stereo"``) adds its own fields."""

from __future__ import annotations

import json

from bayesmachine.region import CAMERA_FPS, VGA_HEIGHT, VGA_WIDTH, OutputRegion

from .targets import Target

__all__ = ["PIXEL_BITS", "VGA_HEIGHT", "VGA_PIXELS", "resources", "machines_that_fit", "stereo_throughput",
           "frame_throughput", "throughput", "markdown"]

VGA_PIXELS = VGA_WIDTH * VGA_HEIGHT
PIXEL_BITS = 16  # a pixel pair of the stereo top's input stream: left and right, 8 bits each


# Gowin's block RAM primitives (one 18-kbit BSRAM each), its distributed RAMs (one CFU each: four
# LUTs hold the memory, nextpnr blocks the CFU's other four LUT sites) and its DSP primitives besides
# the MULT* ones.
_GOWIN_BSRAM = frozenset({"SP", "SPX9", "SDP", "SDPX9", "SDPB", "SDPX9B", "DP", "DPX9", "DPB", "DPX9B",
                          "ROM", "ROMX9", "pROM", "pROMX9"})
_GOWIN_LUTRAM = frozenset({"RAM16S1", "RAM16S2", "RAM16S4", "RAM16SDP1", "RAM16SDP2", "RAM16SDP4"})
_GOWIN_DSP = frozenset({"PADD9", "PADD18", "ALU54D"})
GOWIN_LUTRAM_SITES = 8  # LUT4 sites a Gowin distributed RAM takes (a CFU)


def resources(target: Target, cells: dict[str, int]) -> dict[str, int]:
    """Yosys cell counts in the report's terms: lut4, carry, ff, bram, dsp, lutram."""
    if target.family == "gowin":
        return {
            "lut4": sum(cells.get(f"LUT{k}", 0) for k in range(1, 5)),
            "carry": cells.get("ALU", 0),  # one LUT4 site each, in ALU mode
            "ff": sum(v for k, v in cells.items() if k.startswith("DFF")),
            "bram": sum(v for k, v in cells.items() if k in _GOWIN_BSRAM),
            "dsp": sum(v for k, v in cells.items() if k.startswith("MULT") or k in _GOWIN_DSP),
            "lutram": sum(v for k, v in cells.items() if k in _GOWIN_LUTRAM),
        }
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
    worth (estimate); on iCE40 a carry rides along with its logic cell's LUT; a Gowin ALU takes one
    LUT4 site, a distributed RAM a CFU (:data:`GOWIN_LUTRAM_SITES`)."""
    if target.family == "ecp5":
        return res["lut4"] + 2 * res["carry"] + 4 * res["lutram"]
    if target.family == "gowin":
        return res["lut4"] + res["carry"] + GOWIN_LUTRAM_SITES * res["lutram"]
    return res["lut4"]


def placed_sites(target: Target, pnr_utilization: dict[str, dict[str, int]]) -> dict[str, tuple[int, int]]:
    """What nextpnr placed, (used, available) per kind of site that can bind before LUTs or flip-flops
    alone do: ECP5 slice halves (``TRELLIS_COMB``, ``TRELLIS_FF``), iCE40 logic cells, Gowin LUT4
    sites and flip-flops. nextpnr-himbaechel-gowin's LUT4 count is every LUT4 site taken: it puts a
    blocker LUT on each ALU's site, a distributed RAM's four storage and four blocker LUTs on its CFU,
    and after placement a pass-through LUT on the free site of a flip-flop fed from elsewhere."""
    def get(key: str) -> tuple[int, int]:
        u = pnr_utilization.get(key) or {}
        return u.get("used", 0), u.get("available", 0)

    keys = ("LUT4", "DFF") if target.family == "gowin" else ("TRELLIS_COMB", "TRELLIS_FF", "ICESTORM_LC")
    sites = {k: get(k) for k in keys}
    return {k: v for k, v in sites.items() if v[0] and v[1]}


def utilization(target: Target, res: dict[str, int]) -> dict[str, float]:
    out = {"lut4": logic_cells(target, res) / target.luts, "ff": res["ff"] / target.ffs,
           "bram": res["bram"] / target.brams if target.brams else 0.0}
    out["dsp"] = res["dsp"] / target.dsps if target.dsps else 0.0
    return {k: round(v, 4) for k, v in out.items()}


def machines_that_fit(target: Target, per_machine: dict[str, float], overhead: dict[str, float],
                      fill: float = 0.9) -> int:
    """Machines that fit with every resource at most ``fill`` of the device (place and route needs slack)."""
    best = None
    caps = {"lut4": target.luts, "ff": target.ffs, "bram": target.brams, "dsp": target.dsps}
    for k, cap in caps.items():
        need = per_machine.get(k, 0.0)
        if need <= 0:
            continue
        n = int((fill * cap - overhead.get(k, 0.0)) // need)
        best = n if best is None else min(best, n)
    return max(0, best if best is not None else 0)


def throughput(fmax_mhz: float, machines: int, wall_cycles_per_pixel: float, beats_per_pixel: int,
               load_beat_bits: int) -> dict[str, float]:
    """Pixels/s and VGA frames/s at ``fmax_mhz`` with ``machines`` machines, each taking
    ``wall_cycles_per_pixel`` clock cycles per pixel, all fed by one load stream of one beat per
    cycle (``beats_per_pixel`` beats a pixel): the slower of the two limits wins."""
    f = fmax_mhz * 1e6
    compute_rate = f * machines / wall_cycles_per_pixel
    load_rate = f / beats_per_pixel
    px = min(compute_rate, load_rate)
    return {
        "pixels_per_second": round(px, 1),
        "vga_fps": round(px / VGA_PIXELS, 2),
        "load_bound": load_rate < compute_rate,
        "load_bits_per_second": round(px * beats_per_pixel * load_beat_bits, 1),
    }


def stereo_throughput(fmax_mhz: float | None, wall_cycles_per_pixel: float, width: int, dmax: int,
                      height: int = VGA_HEIGHT, margin: int = 2) -> dict[str, object]:
    """The stereo top's rates for frames of ``width`` x ``height`` pixels (VGA at width 640).

    Every pixel pair of the frame comes in (16 bits, the borders included); results come out for
    the output region, (height - 2 margin) (width - 2 margin - dmax) pixels (the model's margin:
    2, or 3 with a 7x7 census), each taking
    ``wall_cycles_per_pixel`` (the machine's own: it assumes the front end keeps up, as
    benchmarks/bench_frontend.py measures). Without ``fmax_mhz`` only the bits per pixel."""
    try:
        out_px = OutputRegion(height, width, dmax, margin).pixels
    except ValueError:
        raise ValueError(f"a {width}x{height} frame has no output pixel at Dmax {dmax}") from None
    in_bits = PIXEL_BITS * width * height
    tp: dict[str, object] = {
        "frame": f"{width}x{height}",
        "frame_output_pixels": out_px,
        "input_bits_per_pixel": round(in_bits / out_px, 2),
        "assumes": "the front end keeps up with the machine (measured by benchmarks/bench_frontend.py)",
    }
    if fmax_mhz:
        px = fmax_mhz * 1e6 / wall_cycles_per_pixel
        fps = px / out_px
        tp.update({
            "pixels_per_second": round(px, 1),
            "vga_fps": round(fps, 2),
            "input_bits_per_second": round(in_bits * fps, 1),
        })
    return tp


def frame_throughput(fmax_mhz: float | None, frame: dict, width: int,
                     height: int = VGA_HEIGHT) -> dict[str, object]:
    """The stereo top's rates from a frame it ran (``host.throughput.measure_frame``): frames per
    second = fmax / the frame's wall cycles (its first pixel in to its last result out), every pixel
    pair of the ``width`` x ``height`` frame in (16 bits), ``frame["output_pixels"]`` results out.
    ``fmax_for_camera_rate_mhz``: the clock at which that frame would take 1 / CAMERA_FPS seconds.
    Without ``fmax_mhz`` only the cycles, that clock and the bits per pixel."""
    in_bits = PIXEL_BITS * width * height
    out_px, wall = frame["output_pixels"], frame["frame_wall_cycles"]
    tp: dict[str, object] = {
        "frame": f"{width}x{height}",
        "frame_output_pixels": out_px,
        "input_bits_per_pixel": round(in_bits / out_px, 2),
        "frame_pair": frame["pair"],
        "frame_wall_cycles": wall,
        "frame_wall_cycles_per_pixel": frame["wall_cycles_per_pixel"],
        "frame_compute_cycles_per_pixel": frame["compute_cycles_per_pixel"],
        "frame_equals_model": frame["equals_model"],
        "camera_fps": CAMERA_FPS,
        "fmax_for_camera_rate_mhz": round(CAMERA_FPS * wall / 1e6, 1),
    }
    if fmax_mhz:
        fps = fmax_mhz * 1e6 / wall
        tp.update({
            "pixels_per_second": round(fps * out_px, 1),
            "vga_fps": round(fps, 2),
            "input_bits_per_second": round(in_bits * fps, 1),
        })
    return tp


def _fmt(x: float | int | None, digits: int = 1) -> str:
    if x is None:
        return "—"
    if isinstance(x, int):
        return f"{x:,}"
    return f"{x:,.{digits}f}"


def markdown(report: dict) -> str:
    """A human-readable table of the report."""
    r, u = report["resources"], report["utilization"]
    stereo = report.get("stereo")
    fmax = report.get("fmax_mhz")
    provisional = report.get("fmax_provisional") if fmax else None  # reports before the key: None
    mhz = f"{_fmt(fmax)} MHz" + (" (provisional)" if provisional else "")
    tp = report.get("throughput") or {}
    if stereo:
        design = (f"StereoMachine (front end, FIFO of {stereo['fifo_pixels']} pixels = "
                  f"{stereo['fifo_beats']} beats, machine), {stereo['width']}-pixel lines, pixel pairs in; "
                  f"machine: {report['machine_summary']}; wrapper {report['pin_width']}-bit pins.")
        fps_head, fps = f"frames/s ({tp.get('frame', 'W x 480')})", tp.get("vga_fps")
    else:
        design = (f"Machine: {report['machine_summary']}; machines {report['machines']}; "
                  f"wrapper {report['pin_width']}-bit pins.")
        fps_head, fps = "VGA fps (all machines)", tp.get("vga_fps_fit")
    lines = [
        f"# bayesmachine synth: {report['target']} ({report['device']})",
        "",
        design,
        "",
        f"| LUT4 | carry | FF | block RAM | DSP | fmax (MHz) | machines that fit | {fps_head} |",
        "|---|---|---|---|---|---|---|---|",
    ]
    lines.append(
        f"| {_fmt(r['lut4'])} ({u['lut4']:.0%}) | {_fmt(r['carry'])} | {_fmt(r['ff'])} ({u['ff']:.0%}) "
        f"| {_fmt(r['bram'])} | {_fmt(r['dsp'])} | {_fmt(fmax)}{' (provisional)' if provisional else ''} "
        f"| {report['machines_fit']} | {_fmt(fps, 1)} |"
    )
    lines += ["", *_placed_lines(report, provisional)]
    po = report["per_operator"]
    pl = report["per_machine"]
    if stereo:
        lines.append(f"Per operator (front end and FIFO included): {po['lut4']:.1f} LUT4 sites, "
                     f"{po['ff']:.1f} FF. Lanes that fit: copies of the whole StereoMachine, each fed by "
                     "its own pixel stream.")
        buffer_bits = stereo.get("line_buffer_bits", 64)  # reports written before it had the key: 64
        lines += ["", f"Memories (the line buffer, {stereo['width']} x {buffer_bits} bits; the FIFO, "
                  f"{stereo['fifo_beats']} beats of {stereo['beat_bits']} bits; the likelihood tables): "
                  f"{_fmt(r['bram'])} block RAMs ({u['bram']:.0%} of the device) and {_fmt(r['lutram'])} "
                  f"LUT RAMs."]
    else:
        lines.append(f"Per operator: {po['lut4']:.1f} LUT4 sites, {po['ff']:.1f} FF. "
                     f"Per machine: {pl['lut4']:,.0f} LUT4 sites, {pl['ff']:,.0f} FF.")
    cp = report.get("critical_path") or {}
    if cp:
        lines += ["", f"Critical path: {cp['start']} (net {cp['start_net']}) -> {cp['end']} "
                  f"(net {cp['end_net']}): {cp['delay_ns']:.2f} ns "
                  f"({cp['logic_ns']:.2f} ns logic, {cp['routing_ns']:.2f} ns routing, "
                  f"{cp['levels']} logic steps)."]
    if tp and stereo:
        lines += ["", _stereo_text(tp, mhz) + "."]
    elif tp:
        text = (f"Throughput ({tp['pair']}): {tp['compute_cycles_per_pixel']:.2f} compute and "
                f"{tp['wall_cycles_per_pixel']:.2f} wall cycles per pixel (loading included)")
        if tp.get("pixels_per_second") is not None:  # synthesis only: no fmax, no rates
            text += (f"; at {mhz}, {report['machines']} machine(s): "
                     f"{tp['pixels_per_second'] / 1e6:.2f} Mpx/s = {tp['vga_fps']:.1f} VGA fps, load "
                     f"stream {tp['load_bits_per_second'] / 1e9:.2f} Gbit/s"
                     + (" (load-bound)" if tp["load_bound"] else ""))
        lines += ["", text + "."]
        if tp.get("vga_fps_fit") is not None:
            lines.append(f"With the {report['machines_fit']} machines that fit (same fmax assumed, "
                         f"load stream widened to keep up): {tp['vga_fps_fit']:.1f} VGA fps.")
    lines += ["", f"Figures from: {report['measured']}.", ""]
    return "\n".join(lines)


def _placed_lines(report: dict, provisional: str | None) -> list[str]:
    """What nextpnr placed (``placed_sites``) and why the fmax is provisional, each a paragraph."""
    from .targets import get_target

    lines = []
    placed = placed_sites(get_target(report["target"]), report.get("pnr_utilization") or {})
    if placed:
        counts = [f"{used:,} of {available:,} {kind} ({used / available:.0%})"
                  for kind, (used, available) in placed.items()]
        lines += [f"Placed by nextpnr: {', '.join(counts)}.", ""]
    if provisional:
        lines += [f"The fmax is provisional ({provisional}), and so are the rates from it.", ""]
    return lines


def _stereo_text(tp: dict, mhz: str) -> str:
    """The stereo top's throughput sentence: from the frame it ran, else the machine's own cycles;
    ``mhz``: the fmax as the report says it."""
    if "frame_wall_cycles" in tp:
        same = "equal to the model's" if tp["frame_equals_model"] else "DIFFERENT from the model's (a bug)"
        text = (f"Throughput ({tp['frame_pair']}): {tp['frame_wall_cycles']:,} wall cycles for "
                f"{tp['frame_output_pixels']:,} output pixels ({tp['frame_wall_cycles_per_pixel']:.2f} per "
                f"pixel, "
                f"{tp['frame_compute_cycles_per_pixel']:.2f} compute), every result {same}. Input: "
                f"{PIXEL_BITS}-bit pixel pairs, {tp['input_bits_per_pixel']:.2f} bits per output pixel")
    else:
        text = (f"Throughput ({tp['pair']}): {tp['compute_cycles_per_pixel']:.2f} compute and "
                f"{tp['wall_cycles_per_pixel']:.2f} wall cycles per output pixel, the machine's own "
                f"(loading included), assuming {tp['assumes']}. Input: {PIXEL_BITS}-bit pixel pairs, "
                f"every pixel of a {tp['frame']} frame ({tp['frame_output_pixels']:,} output pixels): "
                f"{tp['input_bits_per_pixel']:.2f} bits per output pixel")
    if tp.get("pixels_per_second") is not None:
        text += (f"; at {mhz}: {tp['pixels_per_second'] / 1e6:.2f} Mpx/s = "
                 f"{tp['vga_fps']:.1f} frames/s of {tp['frame']}, input "
                 f"{tp['input_bits_per_second'] / 1e6:.1f} Mbit/s")
    if "fmax_for_camera_rate_mhz" in tp:
        text += f"; {tp['camera_fps']} frames/s would need {tp['fmax_for_camera_rate_mhz']:,.1f} MHz"
    return text


def dumps(report: dict) -> str:
    return json.dumps(report, indent=2, sort_keys=False) + "\n"

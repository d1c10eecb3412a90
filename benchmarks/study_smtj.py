"""Study: the machine with SMTJ random sources, against pseudo-random and ideal sources.

On a pixel subsample of the bundled Middlebury Motorcycle pair (every ``--row-step``-th map
row of the full frame, Dmax 80, the paper's model, counter max 16), runs the machine model with

- the baselines named by ``--baselines``: on-chip kinds of the registry (``lfsr``; ``sobol``
  once it exists) run as they are; ``external`` is the ideal machine (independent uniform
  numbers from NumPy);
- SMTJs in comparator mode (``rng = "smtj"``: W unbiased devices per operator give the
  comparator's number) for each dwell tau of ``--dwells``, with W devices per operator and
  per column (``smtj_share``), and with a device spread of ``--spreads``;
- SMTJs in biased mode (a model variant here, not a machine mode): one device per operator,
  biased so that its stationary probability of state 1 is the word's p = q / 2^W, read directly
  as the operator's bit, no comparator (words 0 and 1.0 are exact gates, as in the machine);
  re-biased at each pixel, so its state carries over from the previous pixel,

and prints RMS error, no-match F1, MAP agreement with the float64 reference, cycles per pixel,
the device count and power; writes the plot (``--plot``, default docs/figures/smtj-study.png)
and a JSON of every figure (``--json``).

    python benchmarks/study_smtj.py [--row-step 8] [--dwells 0.5,1,2,5,10,20,50] [--baselines lfsr,external]
"""

from __future__ import annotations

import json
import math
import os
import sys
import tempfile
import time
from pathlib import Path

import numba
import numpy as np

from bayesmachine.cli import Parser, run_script
from bayesmachine.cliargs import (
    MAX_COUNTER_MAX,
    choice_of,
    float_in_range,
    int_in_range,
    output_path,
    value_list,
)
from bayesmachine.host.features import feature_sums
from bayesmachine.host.images import bundled_pair
from bayesmachine.host.likelihoods import memory_words
from bayesmachine.host.metrics import cycle_stats, f1_score, map_agreement, rms_error
from bayesmachine.host.reference import reference_fast
from bayesmachine.models import ModelParams
from bayesmachine.params import MachineParams, ParameterError
from bayesmachine.sim.model import MachineModel, MachineResult, _finish_cycle, _store
from bayesmachine.sources import SOURCE_KINDS, NumberSource
from bayesmachine.sources.smtj import _GAMMA, _splitmix64, smtj_device_count

DEVICE_POWER_W = 50e-6  # paper, section 5: 50 uW per SMTJ, read at 500 MHz
CLOCK_HZ = 500e6


class UniformSource:
    """Ideal numbers: independent and uniform (NumPy), for the ideal machine."""

    def __init__(self, params: MachineParams, seed: int) -> None:
        self.operators = params.operators
        self._w = params.word_bits
        self._gen = np.random.default_rng(seed)

    def take(self, count: int) -> np.ndarray:
        return self._gen.integers(0, 1 << self._w, size=(count, self.operators), dtype=np.uint16)


def run_fed(params: MachineParams, source: NumberSource, words: np.ndarray, chunk: int) -> MachineResult:
    """The model on ``words``, its entropy port fed from ``source`` as compute cycles need numbers:
    numbers a chunk of pixels did not use stay for the next one, so the stream is contiguous."""
    model = MachineModel(params)
    buf = np.zeros((0, params.operators), np.uint16)
    parts = []
    for s in range(0, len(words), chunk):
        part = words[s : s + chunk]
        need = 40 * len(part)
        while True:
            if len(buf) < need:
                buf = np.concatenate([buf, source.take(need - len(buf))])
            try:
                res = model.run(part, buf)
                break
            except ValueError as exc:
                if "ran out" not in str(exc):
                    raise
                need *= 2
        buf = buf[int(res.cycles.sum()) :]
        parts.append(res)
    return MachineResult.concatenate(parts, params.rows)


@numba.njit(cache=True)
def _run_biased(q, one, tau, f0, f1, state, counter, rows, opcols, n_max, max_cycles, nm_index,
                out_counts, out_map, out_timeout, out_cycles):
    """The machine with one biased SMTJ per operator as its bitstream (no comparator).

    Per pixel each device is re-biased to p = q / one (dwells tau0 = tau f0 / r, tau1 = tau f1 r,
    r = sqrt(p / (1 - p)), f0 and f1 its spread factors) and keeps its state; words 0 and one are
    exact gates. Per cycle the bits are the states, then the devices step (as ``TelegraphBank``)."""
    pixels, ops = q.shape
    thr = np.zeros((ops, 2), np.uint64)
    fixed = np.zeros(ops, np.int8)
    bits = np.zeros(ops, np.uint8)
    counts = np.zeros(rows, np.uint32)
    over = np.zeros(rows, np.uint8)
    scale = 18446744073709551616.0  # 2**64
    for p in range(pixels):
        for o in range(ops):
            qq = q[p, o]
            if qq == 0 or qq == one:
                fixed[o] = 1 if qq == one else 0
            else:
                fixed[o] = -1
                pr = qq / one
                r = math.sqrt(pr / (1.0 - pr))
                a = r / (tau * f0[o])
                b = 1.0 / (tau * r * f1[o])
                s = a + b
                moved = -math.expm1(-s)
                thr[o, 0] = np.uint64(a / s * moved * scale)
                thr[o, 1] = np.uint64(b / s * moved * scale)
        counts[:] = 0
        k = 0
        winner = -1
        while True:
            k += 1
            for o in range(ops):
                if fixed[o] < 0:
                    bits[o] = state[o]
                    counter[o] += _GAMMA
                    if _splitmix64(counter[o]) < thr[o, state[o]]:
                        state[o] ^= 1
                else:
                    bits[o] = fixed[o]
            winner = _finish_cycle(bits, counts, over, rows, opcols, n_max, nm_index)
            if winner >= 0 or k == max_cycles:
                break
        _store(p, counts, k, winner, 1, False, nm_index, out_counts, out_map, out_timeout, out_cycles)


def run_biased(
    params: MachineParams, words: np.ndarray, tau: float, spread: float, seed: int
) -> MachineResult:
    gen = np.random.default_rng([seed, 0xB1A5])
    ops = params.operators
    z = gen.standard_normal((2, ops))
    state = (gen.random(ops) < 0.5).astype(np.uint8)
    counter = gen.integers(0, 1 << 64, size=ops, dtype=np.uint64, endpoint=False)
    q = words.reshape(len(words), ops).astype(np.int64)
    n = len(q)
    out = MachineResult(np.zeros((n, params.rows), np.uint32), np.zeros(n, np.int32), np.zeros(n, bool),
                        np.zeros(n, bool), np.zeros(n, np.int64))
    nm = params.rows - 1
    _run_biased(q, params.word_one, float(tau), np.exp(spread * z[0]), np.exp(spread * z[1]), state, counter,
                params.rows, params.operator_columns, params.counter_max, params.max_cycles, nm,
                out.counts, out.map, out.timeout, out.cycles)
    out.nomatch[:] = (~out.timeout) & (out.map == nm)
    return out


def figures(res: MachineResult, params: MachineParams, posterior: np.ndarray, ref_map: np.ndarray) -> dict:
    disp = np.where(res.nomatch | res.timeout, -1, res.map)
    ref_nm = ref_map < 0
    cyc = cycle_stats(res.cycles)
    return {
        "rms": rms_error(res.counts, params.counter_max, posterior, ~ref_nm),
        "f1": f1_score(disp < 0, ref_nm),
        "map_agreement": map_agreement(disp, ref_map),
        "cycles": cyc["mean"],
        "cycles_median": cyc["median"],
        "timeouts": int(res.timeout.sum()),
    }


def main(argv: list[str] | None = None) -> None:
    ap = Parser(prog=Path(__file__).name, description=__doc__.split("\n\n")[0])
    dwells = value_list(float_in_range(1e-6, 1e12), "dwell")
    ap.add_argument("--row-step", type=int_in_range(1, 500), default=8,
                    help="every N-th map row of the frame, 1 .. 500 (default 8)")
    ap.add_argument("--counter-max", type=int_in_range(1, MAX_COUNTER_MAX), default=16,
                    help="counter max n_max (default 16)")
    ap.add_argument("--dwells", type=dwells, default="0.5,1,2,5,10,20,50",
                    help="SMTJ dwell tau values, clock cycles, each in [1e-6, 1e12] (default %(default)s)")
    ap.add_argument("--spreads", type=value_list(float_in_range(0, 1), "spread"), default="0,0.05,0.1,0.2",
                    help="device spreads (log-sd, 0 .. 1), at --spread-dwells (default %(default)s)")
    ap.add_argument("--spread-dwells", type=dwells, default="1,5",
                    help="dwells at which the spreads are measured (default %(default)s)")
    ap.add_argument("--baselines", type=value_list(choice_of(SOURCE_KINDS), "baseline"),
                    default="lfsr,external",
                    help="registry kinds to compare with (external = ideal uniform numbers)")
    ap.add_argument("--seed", type=int_in_range(0, 2**64 - 1), default=1,
                    help="machine seed: LFSRs, SMTJ devices (default 1)")
    ap.add_argument("--noise-seeds", type=int_in_range(0, 100), default=4,
                    help="also run the ideal machine with this many other seeds: seed-to-seed noise")
    ap.add_argument("--plot", type=output_path, default=Path("docs/figures/smtj-study.png"),
                    help="figure to write (default %(default)s)")
    ap.add_argument("--json", type=output_path, default=None, help="also write every figure as JSON here")
    args = ap.parse_args(argv)
    dwell_list, spreads, spread_dwells = args.dwells, args.spreads, args.spread_dwells
    baselines = args.baselines
    try:  # every machine of the study, validated before the first run
        for tau in {*dwell_list, *spread_dwells}:
            for s in spreads:
                MachineParams.for_disparity(80, rng="smtj", smtj_dwell=tau, smtj_spread=s,
                                            counter_max=args.counter_max, seed=args.seed)
    except ParameterError as exc:
        ap.error(str(exc))

    t0 = time.perf_counter()
    model = ModelParams(name="paper")
    left, right, _ = bundled_pair()
    fl, fr = feature_sums(left), feature_sums(right)
    ref = reference_fast(fl, fr, model)
    base = MachineParams.for_disparity(model.dmax, counter_max=args.counter_max, seed=args.seed)
    rows = np.arange(0, ref.map.shape[0], args.row_step)
    words = np.concatenate(
        [memory_words(fl, fr, model, base, rows=slice(r, r + 1)) for r in rows]
    )
    posterior, ref_map = ref.posterior[rows].reshape(len(words), -1), ref.map[rows].reshape(-1)
    chunk = ref.map.shape[1]
    print(f"bundled Motorcycle, every {args.row_step}th map row: {len(words)} pixels, Dmax {model.dmax}, "
          f"counter max {args.counter_max}, W {base.word_bits}, seed {args.seed}  (prepared in "
          f"{time.perf_counter() - t0:.1f} s)")

    results: list[dict] = []

    def record(
        name: str, group: str, res: MachineResult, params: MachineParams, seconds: float, **extra: object
    ) -> None:
        f = figures(res, params, posterior, ref_map)
        row = {"name": name, "group": group, **extra, **f, "seconds": seconds}
        results.append(row)
        print(f"  {name:38s} RMS {f['rms']:.4f}  F1 {f['f1']:.4f}  MAP agr {f['map_agreement']:.4f}  "
              f"cycles/px {f['cycles']:7.2f} (median {f['cycles_median']:.0f})  timeouts {f['timeouts']}  "
              f"[{seconds:.1f} s]", flush=True)

    def smtj_params(**kw: object) -> MachineParams:
        return MachineParams(**{**base.to_dict(), "rng": "smtj", **kw})  # type: ignore[arg-type]

    print("baselines:")
    for kind in baselines:
        p = MachineParams(**{**base.to_dict(), "rng": kind})  # type: ignore[arg-type]
        t = time.perf_counter()
        if SOURCE_KINDS[kind].on_chip:
            res = MachineModel(p).run(words)
        else:
            src = SOURCE_KINDS[kind].numbers
            source = src(p) if src is not None else UniformSource(p, args.seed)
            res = run_fed(p, source, words, chunk)
        record("ideal (independent uniform)" if kind == "external" else kind, "baseline", res, p,
               time.perf_counter() - t, kind=kind)

    if args.noise_seeds:
        ideal_params = MachineParams(**{**base.to_dict(), "rng": "external"})  # type: ignore[arg-type]
        noise = []
        for k in range(1, args.noise_seeds + 1):
            res = run_fed(ideal_params, UniformSource(ideal_params, args.seed + k), words, chunk)
            noise.append(figures(res, ideal_params, posterior, ref_map))
        keys = ("rms", "f1", "map_agreement", "cycles")
        sd = {key: float(np.std([f[key] for f in noise], ddof=1)) for key in keys}
        print(f"  seed-to-seed sd of the ideal machine ({args.noise_seeds} seeds): RMS {sd['rms']:.4f}  "
              f"F1 {sd['f1']:.4f}  MAP agr {sd['map_agreement']:.4f}  cycles/px {sd['cycles']:.2f}")
    else:
        sd = None

    for share in ("operator", "column"):
        print(f"SMTJ comparator mode, W devices per {share}, no spread:")
        for tau in dwell_list:
            p = smtj_params(smtj_dwell=tau, smtj_share=share)
            t = time.perf_counter()
            res = run_fed(p, SOURCE_KINDS["smtj"].numbers(p), words, chunk)  # type: ignore[misc]
            record(f"smtj per {share}, tau {tau:g}", f"comparator-{share}", res, p, time.perf_counter() - t,
                   tau=tau, spread=0.0, devices=smtj_device_count(p))

    print("SMTJ comparator mode, W devices per operator, device spread:")
    for tau in spread_dwells:
        for s in spreads:
            if s == 0:
                continue
            p = smtj_params(smtj_dwell=tau, smtj_spread=s)
            t = time.perf_counter()
            res = run_fed(p, SOURCE_KINDS["smtj"].numbers(p), words, chunk)  # type: ignore[misc]
            record(f"smtj per operator, tau {tau:g}, spread {s:g}", "spread", res, p, time.perf_counter() - t,
                   tau=tau, spread=s, devices=smtj_device_count(p))

    print("SMTJ biased mode (one device per operator, p = q / 2^W, model variant):")
    for s in (0.0, *[v for v in spreads if v]):
        for tau in dwell_list if s == 0 else spread_dwells:
            t = time.perf_counter()
            res = run_biased(base, words, tau, s, args.seed)
            record(f"biased, tau {tau:g}" + (f", spread {s:g}" if s else ""), "biased", res, base,
                   time.perf_counter() - t, tau=tau, spread=s, devices=base.operators)

    # From which tau the device must be read more slowly: the largest measured tau whose figures stay
    # within 10 % (RMS) and 0.01 (F1) of the ideal machine; a device of dwell tau read every k cycles
    # is a device of dwell tau / k, so a longer dwell needs k = ceil(tau / tau_ok) (k times the time).
    ideal = next((r for r in results if r.get("kind") == "external"), None)
    limits = {}
    if ideal is not None:
        print("largest dwell within 10 % of the ideal RMS and 0.01 of its F1 (read interval k = tau / that):")
        for group in ("comparator-operator", "comparator-column", "biased"):
            ok = [r["tau"] for r in results if r["group"] == group and r["spread"] == 0
                  and r["rms"] <= 1.1 * ideal["rms"] and r["f1"] >= ideal["f1"] - 0.01]
            good = max(ok) if ok else None
            worse = [r["tau"] for r in results if r["group"] == group and r["spread"] == 0
                     and good is not None and r["tau"] <= good and r["tau"] not in ok]
            limits[group] = good
            print(f"  {group:22s} tau <= {good if good is not None else 'none measured'}"
                  + (f" (but not at tau {worse})" if worse else ""))

    ops = base.operators
    power = [
        ("comparator, W per operator", base.word_bits * ops),
        ("comparator, W per column (shared by rows)", base.word_bits * base.operator_columns),
        ("biased, one per operator (the paper's 246)", ops),
    ]
    print("devices and power (50 uW per SMTJ):")
    for name, n in power:
        print(f"  {name:45s} {n:5d} devices  {n * DEVICE_POWER_W * 1e3:7.2f} mW")

    summary = {
        "pixels": int(len(words)), "row_step": args.row_step, "counter_max": args.counter_max,
        "word_bits": base.word_bits, "seed": args.seed, "results": results,
        "tau_limits": limits,
        "seed_sd": sd,
        "devices": [{"mode": name, "devices": n, "power_mW": n * DEVICE_POWER_W * 1e3} for name, n in power],
        "seconds": time.perf_counter() - t0,
    }
    print(f"total {summary['seconds']:.0f} s")
    if args.json is not None:
        _atomic_write(args.json, (json.dumps(summary, indent=2) + "\n").encode())
        print(f"wrote {args.json}")
    if args.plot is not None:
        plot(summary, args.plot)
        print(f"wrote {args.plot}")


def _atomic_write(path: Path, data: bytes) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=path.suffix)
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)  # mkstemp makes 0600 files
        os.replace(tmp, path)
    except BaseException:
        os.unlink(tmp)
        raise


def plot(summary: dict, path: Path) -> None:
    import io

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    res = summary["results"]
    fig, axes = plt.subplots(1, 4, figsize=(17, 4.2))
    keys = [("rms", "RMS error (counts vs posterior)"), ("f1", "no-match F1"),
            ("cycles", "cycles per pixel (mean)")]
    curves = [("comparator-operator", "SMTJ comparator, W per operator", "C0", "o"),
              ("comparator-column", "SMTJ comparator, W per column", "C1", "s"),
              ("biased", "SMTJ biased, 1 per operator", "C2", "^")]
    for ax, (key, label) in zip(axes[:3], keys, strict=True):
        for group, name, color, marker in curves:
            pts = [r for r in res if r["group"] == group and r.get("spread", 0) == 0]
            ax.plot([r["tau"] for r in pts], [r[key] for r in pts], marker=marker, color=color, label=name)
        for i, r in enumerate(r for r in res if r["group"] == "baseline"):
            ax.axhline(r[key], color=f"C{3 + i}", ls="--", lw=1, label=r["name"])
        ax.set_xscale("log")
        ax.set_xlabel("SMTJ dwell tau (clock cycles)")
        ax.set_title(label)
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=7)
    ax = axes[3]
    for group, marker in (("spread", "o"), ("biased", "^")):
        taus = sorted({r["tau"] for r in res if r["group"] == group and r["spread"] > 0})
        for j, tau in enumerate(taus):
            groups = (group, "comparator-operator" if group == "spread" else group)
            pts = [r for r in res if r["group"] in groups and r["tau"] == tau]
            pts.sort(key=lambda r: r["spread"])
            label = ("comparator" if group == "spread" else "biased") + f", tau {tau:g}"
            ax.plot([100 * r["spread"] for r in pts], [r["f1"] for r in pts], marker=marker,
                    color=f"C{j + (0 if group == 'spread' else 2)}", label=label)
    ax.set_xlabel("device spread (log-sd of each dwell, %)")
    ax.set_title("no-match F1 vs device spread")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    fig.suptitle(f"SMTJ random sources, bundled Motorcycle pair ({summary['pixels']} px), "
                 f"counter max {summary['counter_max']}, W = {summary['word_bits']}", fontsize=10)
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110)
    plt.close(fig)
    _atomic_write(path, buf.getvalue())


if __name__ == "__main__":
    sys.exit(run_script(Path(__file__).name, main))

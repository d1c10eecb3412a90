# amaranth: UnusedElaboratable=no
"""The SMTJ device model (``bayesmachine.sources.smtj``) and the ``"smtj"`` random source.

- the sampled telegraph process: geometric run lengths of the right mean per state (chi-square),
  stationary probability, lag-1 autocorrelation, per-device spread statistics;
- the number source: seeded, continuable, W-bit numbers, per-operator or per-column devices;
- the machine with ``rng = "smtj"``: the same RTL as ``"external"``; the model and the RTL in
  Amaranth's simulator agree bit for bit when fed the SMTJ numbers.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import assert_same_results, run_sim, small_params
from scipy import stats

from bayesmachine.params import RNG_KINDS, MachineParams, ParameterError
from bayesmachine.sim.model import MachineModel, MachineResult
from bayesmachine.sim.synthetic import synthetic_disparity_words
from bayesmachine.sources import SOURCE_KINDS
from bayesmachine.sources.smtj import (
    SMTJSource,
    TelegraphBank,
    dwells,
    flip_probabilities,
    smtj_device_count,
)


def _runs(states: np.ndarray) -> dict[int, np.ndarray]:
    """Complete run lengths of each state, per device column (first and last runs cut off)."""
    out: dict[int, list[np.ndarray]] = {0: [], 1: []}
    for col in states.T:
        edges = np.flatnonzero(np.diff(col)) + 1
        lengths = np.diff(edges)
        first_state = col[edges[0]] if len(edges) else 0
        for s in (0, 1):
            out[s].append(lengths[(np.arange(len(lengths)) % 2 == 0) == (first_state == s)])
    return {s: np.concatenate(v) for s, v in out.items()}


@pytest.mark.parametrize("tau, bias", [(1.0, 0.5), (8.0, 0.3), (30.0, 0.5)])
def test_dwell_times_are_geometric_with_the_exact_mean(tau: float, bias: float) -> None:
    bank = TelegraphBank(200, tau, bias, seed=11)
    runs = _runs(bank.take(30_000))
    tau0, tau1 = dwells(tau, bias)
    flips = flip_probabilities(tau0, tau1)  # P(0 -> 1), P(1 -> 0)
    for s in (0, 1):
        q = float(flips[s])
        lengths = runs[s]
        assert len(lengths) > 5000
        mean = lengths.mean()
        # Geometric on {1, 2, ...}: mean 1/q, sd sqrt(1-q)/q.
        assert abs(mean - 1 / q) < 5 * math.sqrt(1 - q) / q / math.sqrt(len(lengths)), (s, mean, 1 / q)
        # Chi-square goodness of fit: bins 1..K-1 and a tail bin holding >= K.
        k = max(3, int(3 / q))
        observed = np.bincount(np.minimum(lengths, k), minlength=k + 1)[1:]
        pmf = q * (1 - q) ** np.arange(k - 1)
        expected = len(lengths) * np.append(pmf, (1 - q) ** (k - 1))
        keep = expected > 5
        obs, exp = observed[keep], expected[keep]
        exp = exp * obs.sum() / exp.sum()
        _, pval = stats.chisquare(obs, exp)
        assert pval > 1e-4, (s, pval)
    if tau >= 30:  # long dwells: run lengths tend to the continuous mean dwells (+3.4 % here)
        assert abs(runs[0].mean() / tau0 - 1) < 0.06 and abs(runs[1].mean() / tau1 - 1) < 0.06


@pytest.mark.parametrize("tau", [0.2, 1.0, 20.0])
@pytest.mark.parametrize("bias", [0.15, 0.5, 0.8])
def test_stationary_probability_and_autocorrelation(tau: float, bias: float) -> None:
    bank = TelegraphBank(400, tau, bias, seed=5)
    x = bank.take(5_000).astype(np.float64)
    tau0, tau1 = dwells(tau, bias)
    rho = math.exp(-(1 / tau0 + 1 / tau1))  # lag-1 autocorrelation of the sampled process
    n_eff = x.size * (1 - rho) / (1 + rho)
    assert abs(x.mean() - bias) < 5 * math.sqrt(bias * (1 - bias) / n_eff), (x.mean(), bias)
    c = x - bias
    lag1 = float((c[1:] * c[:-1]).mean() / (c * c).mean())
    assert abs(lag1 - rho) < 0.02, (lag1, rho)


def test_device_spread_statistics() -> None:
    s, n = 0.1, 20_000
    bank = TelegraphBank(n, 10.0, 0.5, spread=s, seed=2)
    z0 = np.log(bank.tau0 / 10.0) / s
    z1 = np.log(bank.tau1 / 10.0) / s
    for z in (z0, z1):
        assert abs(z.mean()) < 5 / math.sqrt(n) and abs(z.std() - 1) < 0.03
    logit = np.log(bank.bias / (1 - bank.bias))
    assert abs(logit.std() - s * math.sqrt(2)) < 0.01 * s * 10
    assert abs(np.log(bank.tau).std() - s / math.sqrt(2)) < 0.005
    assert abs(np.corrcoef(z0, z1)[0, 1]) < 0.05  # the two barriers scatter independently
    same = TelegraphBank(100, 10.0, 0.5, spread=0.0, seed=2)
    assert np.all(same.tau0 == 10.0) and np.all(same.bias == 0.5)


def test_per_device_bias_is_what_each_device_emits() -> None:
    bank = TelegraphBank(50, 2.0, 0.5, spread=0.3, seed=9)
    x = bank.take(40_000)
    got = x.mean(axis=0)
    assert np.abs(got - bank.bias).max() < 0.02
    assert bank.bias.std() > 0.05  # the spread is visible device by device


def _smtj(**kwargs: object) -> MachineParams:
    return MachineParams.for_disparity(6, rng="smtj", word_bits=6, **kwargs)  # type: ignore[arg-type]


def test_source_is_seeded_and_continuable() -> None:
    p = _smtj(smtj_dwell=3.0, smtj_spread=0.05, seed=7)
    whole = SMTJSource(p).take(500)
    src = SMTJSource(p)
    parts = np.concatenate([src.take(0), src.take(137), src.take(1), src.take(362)])
    assert np.array_equal(parts, whole)
    src.reset()
    assert np.array_equal(src.take(500), whole)
    other = SMTJSource(MachineParams(**{**p.to_dict(), "seed": 8})).take(500)  # type: ignore[arg-type]
    assert not np.array_equal(other, whole)
    with pytest.raises(ValueError, match="count"):
        src.take(-1)


@pytest.mark.parametrize("dwell", [0.5, 1.0, 20.0])
def test_numbers_are_w_bit_and_uniform_in_the_long_run(dwell: float) -> None:
    p = _smtj(smtj_dwell=dwell)
    src = SMTJSource(p)
    nums = src.take(4_000)
    assert nums.dtype == np.uint16 and nums.shape == (4_000, p.operators)
    assert nums.min() >= 0 and nums.max() < (1 << p.word_bits)
    assert src.devices == smtj_device_count(p) == p.word_bits * p.operators
    bits = (nums[..., None] >> np.arange(p.word_bits)) & 1
    # Each bit is one unbiased device; its mean over time and operators is 1/2.
    rho = math.exp(-2 / dwell)
    n_eff = 4_000 * p.operators * (1 - rho) / (1 + rho)
    assert np.all(np.abs(bits.mean(axis=(0, 1)) - 0.5) < 5 * 0.5 / math.sqrt(n_eff))


def test_column_sharing_gives_every_row_its_column_number() -> None:
    p = _smtj(smtj_dwell=2.0, smtj_share="column")
    nums = SMTJSource(p).take(300).reshape(300, p.rows, p.operator_columns)
    assert np.all(nums == nums[:, :1, :])
    assert not np.array_equal(nums[:, 0, 0], nums[:, 0, 1])
    assert smtj_device_count(p) == p.word_bits * p.operator_columns
    per_op = SMTJSource(_smtj(smtj_dwell=2.0)).take(300).reshape(300, p.rows, p.operator_columns)
    assert not np.array_equal(per_op[:, 0, :], per_op[:, 1, :])


def test_registry_and_parameters() -> None:
    assert tuple(SOURCE_KINDS) == RNG_KINDS
    kind = SOURCE_KINDS["smtj"]
    assert not kind.on_chip and kind.numbers is not None
    p = _smtj(smtj_dwell=20)
    assert isinstance(kind.numbers(p), SMTJSource)
    assert p.smtj_dwell == 20.0 and p.fingerprint() == _smtj(smtj_dwell=20.0).fingerprint()
    assert p.fingerprint() != _smtj(smtj_dwell=21).fingerprint()
    assert "smtj_dwell" in p.to_dict()
    lfsr = MachineParams.for_disparity(6)
    assert "smtj_dwell" not in lfsr.to_dict()  # meaningless to other sources: not in reports or caches
    with pytest.raises(ParameterError, match="rng = 'smtj'"):
        SMTJSource(lfsr)


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"smtj_dwell": 0}, "smtj_dwell"),
        ({"smtj_dwell": -1.0}, "smtj_dwell"),
        ({"smtj_dwell": float("inf")}, "smtj_dwell"),
        ({"smtj_spread": 1.5}, "smtj_spread"),
        ({"smtj_spread": -0.1}, "smtj_spread"),
        ({"smtj_share": "row"}, "smtj_share"),
    ],
)
def test_bad_device_parameters_name_the_problem(kwargs: dict, message: str) -> None:
    with pytest.raises(ParameterError, match=message) as err:
        _smtj(**kwargs)
    assert err.value.parameter == message


def test_a_device_parameter_of_the_wrong_type_is_a_type_error() -> None:
    with pytest.raises(TypeError, match="^smtj_dwell"):
        _smtj(smtj_dwell="5")


def test_bank_rejects_bad_device_values() -> None:
    with pytest.raises(ParameterError, match="bias"):
        TelegraphBank(4, 2.0, 1.0)
    with pytest.raises(ParameterError, match="tau"):
        TelegraphBank(4, 0.0)
    with pytest.raises(ParameterError, match="devices"):
        TelegraphBank(0, 2.0)


@pytest.mark.eda
def test_smtj_machine_is_the_external_rtl() -> None:
    from bayesmachine.hdl.emit import verilog_text
    from bayesmachine.hdl.machine import BayesianMachine

    smtj = small_params(rng="smtj", smtj_dwell=4.0)
    ext = small_params(rng="external")
    assert "entropy" in BayesianMachine(params=smtj).signature.members
    assert verilog_text(BayesianMachine(params=smtj)) == verilog_text(BayesianMachine(params=ext))


@pytest.mark.parametrize("dwell, share", [(1.0, "operator"), (20.0, "column")])
def test_model_and_rtl_agree_on_smtj_numbers(dwell: float, share: str) -> None:
    from bayesmachine.sim.pysim import PysimEngine

    params = small_params(rng="smtj", smtj_dwell=dwell, smtj_share=share, seed=4)
    words = synthetic_disparity_words(params, 12, np.random.default_rng(3))
    # No numbers given: each engine drives the entropy port from its own seeded device model.
    want = MachineModel(params).run(words)
    assert int(want.cycles.sum()) > 12 * (params.counter_max + 1) - 1
    assert_same_results(PysimEngine(params).run(words), want)
    # ... and those numbers are the devices' states, read once per compute cycle and packed as
    # docs/smtj.md says: bit k of operator o = r * C + c from device o * W + k ("operator") or
    # c * W + k ("column"). Packed here from the bank's own per-device samples, not by SMTJSource.
    w, cols = params.word_bits, params.operator_columns
    devices = w * (params.operators if share == "operator" else cols)
    states = TelegraphBank(devices, dwell, 0.5, params.smtj_spread, params.seed).take(int(want.cycles.sum()))
    first = [(o if share == "operator" else o % cols) * w for o in range(params.operators)]
    numbers = np.stack([sum(states[:, f + k].astype(np.int64) << k for k in range(w)) for f in first], axis=1)
    assert_same_results(MachineModel(params).run(words, numbers), want)


@pytest.mark.eda
def test_verilator_agrees_on_smtj_numbers(verilator_toolchain: object, verilator_cache: object) -> None:
    from bayesmachine.sim.verilator import VerilatorEngine

    # The RTL (hence the Verilator build, shared in a session) of test_engines' external machine.
    params = MachineParams.for_disparity(6, words_per_beat=4, rng="smtj", smtj_dwell=20.0, seed=5,
                                         max_cycles=60)
    words = synthetic_disparity_words(params, 40, np.random.default_rng(8))
    want = MachineModel(params).run(words)
    with VerilatorEngine(params, build_dir=verilator_cache) as eng:
        got = eng.run(words[:15])
        got = MachineResult.concatenate([got, eng.run(words[15:])], params.rows)
    assert_same_results(got, want)


@pytest.mark.eda
def test_emit_cli_smtj_machine(tmp_path, capsys: pytest.CaptureFixture[str]) -> None:
    from bayesmachine.cli import main

    out = tmp_path / "smtj.v"
    assert main(["emit", "--model", "paper", "--dmax", "2", "--rng", "smtj", "--smtj-dwell", "20",
                 "--smtj-share", "column",
                 "-o", str(out)]) == 0
    text = capsys.readouterr().out
    assert "simulated by 30 SMTJ devices, 10 per column: dwell 20 cycles" in text
    assert "entropy" in text and "input [119:0] entropy" in out.read_text()
    # Device options without the SMTJ source are a one-line error, not silently ignored.
    assert main(["emit", "--dmax", "2", "--smtj-spread", "0.05", "-o", str(tmp_path / "x.v")]) == 2
    assert "--smtj-spread: device options of --rng smtj" in capsys.readouterr().err
    assert not (tmp_path / "x.v").exists()


def test_xor_of_devices_decorrelates_like_a_shorter_dwell() -> None:
    # The docs' advice for long dwells: the XOR of m unbiased devices of dwell tau has the
    # autocorrelation of one device of dwell tau / m, exp(-2 m k / tau).
    tau, m = 12.0, 3
    x = TelegraphBank(m * 300, tau, seed=21).take(6_000).reshape(6_000, m, 300)
    xor = np.bitwise_xor.reduce(x, axis=1).astype(np.float64)
    c = xor - 0.5
    for lag in (1, 4):
        got = float((c[lag:] * c[:-lag]).mean() / (c * c).mean())
        assert abs(got - math.exp(-2 * m * lag / tau)) < 0.02, (lag, got)
    assert abs(xor.mean() - 0.5) < 0.01


# --- The synthesizable SMTJ emulator (hdl/smtj.py) and its twin ---


def test_emulator_twin_statistics_follow_the_device_model() -> None:
    from bayesmachine.sources.smtj import SMTJEmulatorTwin

    p = _smtj(smtj_dwell=5.0)
    nums = SMTJEmulatorTwin(p).take(20_000)
    bits = ((nums[..., None] >> np.arange(p.word_bits)) & 1).reshape(20_000, -1).astype(np.float64)
    rho = math.exp(-2 / 5.0)
    n_eff = bits.size * (1 - rho) / (1 + rho)
    assert abs(bits.mean() - 0.5) < 5 * 0.5 / math.sqrt(n_eff)
    c = bits - 0.5
    assert abs(float((c[1:] * c[:-1]).mean() / (c * c).mean()) - rho) < 0.02
    twin = SMTJEmulatorTwin(p)
    assert np.array_equal(np.concatenate([twin.take(11), twin.take(89)]), nums[:100])


def test_emulator_rtl_matches_its_twin() -> None:
    from bayesmachine.hdl.smtj import SMTJEmulator
    from bayesmachine.sources.smtj import SMTJEmulatorTwin

    p = small_params(rng="smtj", smtj_dwell=2.0, smtj_spread=0.1, seed=6)
    dut = SMTJEmulator(params=p)
    want = SMTJEmulatorTwin(p).take(120)
    advance = np.random.default_rng(1).random(200) < 0.6
    raw = dut.numbers.as_value()
    w = p.word_bits

    async def bench(ctx):
        row = 0
        for adv in advance:
            got = ctx.get(raw)
            assert [(got >> (o * w)) & ((1 << w) - 1) for o in range(p.operators)] == want[row].tolist(), row
            ctx.set(dut.advance, int(adv))
            await ctx.tick()
            row += int(adv)
            if row == len(want):
                break

    run_sim(dut, bench)


def test_emulated_machine_equals_the_model_on_the_twin_numbers() -> None:
    from amaranth.sim import Simulator

    from bayesmachine.hdl.smtj import SMTJEmulatedMachine
    from bayesmachine.sim.packing import pack_beats
    from bayesmachine.sim.results import decode_results
    from bayesmachine.sources.smtj import SMTJEmulatorTwin

    p = small_params(rng="smtj", smtj_dwell=3.0, smtj_share="column", seed=2)
    words = synthetic_disparity_words(p, 10, np.random.default_rng(4))
    want = MachineModel(p).run(words, SMTJEmulatorTwin(p).take(10 * p.max_cycles))
    dut = SMTJEmulatedMachine(params=p)
    beats = [b for pixel in words for b in pack_beats(p, pixel)]
    raws: list[int] = []

    async def feeder(ctx):
        for b in beats:
            ctx.set(dut.load.valid, 1)
            ctx.set(dut.load.payload.as_value(), b)
            await ctx.tick().until(dut.load.ready)
        ctx.set(dut.load.valid, 0)

    async def collector(ctx):
        ctx.set(dut.result.ready, 1)
        while len(raws) < len(words):
            _, _, valid, payload = await ctx.tick().sample(dut.result.valid, dut.result.payload.as_value())
            if valid:
                raws.append(payload)

    sim = Simulator(dut)
    sim.add_clock(1e-8)
    sim.add_testbench(feeder, background=True)
    sim.add_testbench(collector)
    sim.run()
    got = decode_results(p, raws)
    assert_same_results(got, want)


def test_run_and_sweep_options_build_smtj_machines() -> None:
    from bayesmachine.cli import build_parser
    from bayesmachine.cliargs import model_params_from_args
    from bayesmachine.host.cli.options import machine_params

    parser = build_parser()
    for cmd in (["run"], ["sweep"]):
        args = parser.parse_args(cmd + ["--rng", "smtj", "--smtj-dwell", "20", "--smtj-spread", "0.05",
                                        "--smtj-share", "column", "-o", "out"])
        rng = args.rng[0] if cmd == ["sweep"] else None  # sweep takes a list of sources
        p = machine_params(args, model_params_from_args(args), 16, rng)
        assert (p.rng, p.smtj_dwell, p.smtj_spread, p.smtj_share) == ("smtj", 20.0, 0.05, "column")
        args = parser.parse_args(cmd + ["--smtj-dwell", "20", "-o", "out"])
        with pytest.raises(ValueError, match="--smtj-dwell: device options of --rng smtj"):
            machine_params(args, model_params_from_args(args), 16)


@pytest.mark.slow  # a benchmark script end to end (20 s)
def test_study_script_runs_and_writes_complete_outputs(tmp_path) -> None:
    import json
    import subprocess
    import sys
    from pathlib import Path

    script = Path(__file__).resolve().parents[2] / "benchmarks" / "study_smtj.py"
    plot, out = tmp_path / "study.png", tmp_path / "study.json"
    proc = subprocess.run(
        [sys.executable, str(script), "--row-step", "400", "--dwells", "0.5,20", "--spreads", "0,0.1",
         "--spread-dwells", "1", "--noise-seeds", "2", "--plot", str(plot), "--json", str(out)],
        capture_output=True, text=True, timeout=600,
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    summary = json.loads(out.read_text())
    groups = {r["group"] for r in summary["results"]}
    assert groups == {"baseline", "comparator-operator", "comparator-column", "spread", "biased"}
    assert all(math.isfinite(r["rms"]) and 0 <= r["f1"] <= 1 for r in summary["results"])
    by = {r["name"]: r for r in summary["results"]}
    # Long dwells are much worse than the ideal machine, even on one map row.
    assert by["smtj per operator, tau 20"]["rms"] > 1.5 * by["ideal (independent uniform)"]["rms"]
    assert [d["devices"] for d in summary["devices"]] == [2460, 30, 246]
    assert plot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"

"""The SMTJ random source: a device model of superparamagnetic tunnel junctions (pure Python + numba).

A superparamagnetic tunnel junction flips between two magnetic states at random (telegraph
noise). The model, per device:

- **Continuous time.** The device dwells in state ``s`` for an exponentially distributed time
  of mean ``tau_s`` clock cycles, then flips: a two-state Markov process with rates
  ``a = 1 / tau_0`` (0 -> 1) and ``b = 1 / tau_1`` (1 -> 0). Its stationary probability of
  state 1 is ``p = tau_1 / (tau_0 + tau_1)``.
- **Parametrization (dwell tau, bias p).** A bias current or field tilts the energy barrier:
  one state's dwell grows by the factor the other's shrinks (Neel-Arrhenius), so
  ``tau_1 = tau * sqrt(p / (1 - p))`` and ``tau_0 = tau * sqrt((1 - p) / p)``: ``tau`` is the
  geometric mean of the two mean dwells (the mean dwell of an unbiased device, p = 1/2) and
  ``p`` the stationary probability of state 1.
- **Sampling once per clock cycle, exactly.** The state read at cycle t + 1 given the state
  at t follows ``exp(Q)`` of the continuous process (flips that undo themselves within a cycle
  are invisible, as in a real read-out):
  ``P(0 -> 1) = a / (a + b) * (1 - exp(-(a + b)))`` and
  ``P(1 -> 0) = b / (a + b) * (1 - exp(-(a + b)))``. The sampled sequence is a two-state
  Markov chain with exactly the stationary probability p at any tau, geometric run lengths of
  mean ``1 / P(s -> not s)`` per state (tending to ``tau_s`` when tau >> 1), and lag-k
  autocorrelation ``exp(-k (a + b))`` (for an unbiased device, ``exp(-2k / tau)``): never
  negative, however short tau.
- **Device spread.** Real devices differ. With spread ``s``, each device's two mean dwells are
  multiplied by independent lognormal factors ``exp(s * z)``, ``z ~ N(0, 1)`` (Gaussian
  scatter of the two energy barriers): its tau scatters with log-sd ``s / sqrt(2)`` and its
  log-odds ``log(p / (1 - p))`` with sd ``s * sqrt(2)`` (about ``0.35 s`` in p at p = 1/2).
- **Seeds.** Every device's spread factors, initial state (drawn from its own stationary
  distribution) and flip stream derive from one seed; each device has its own splitmix64
  stream, so a bank's output is the same however it is taken in pieces.

``SMTJSource(params)`` is the machine's ``"smtj"`` source: each compute cycle, each operator's
W-bit random number for the comparator is read from W unbiased devices (bit k from device k).
With ``params.smtj_share == "column"`` the W devices of a column are shared by all rows of
that column (W per column instead of W per operator), like the shared pseudo-random sources.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numba
import numpy as np

from bayesmachine.checks import as_int, as_real
from bayesmachine.errors import ParameterError

if TYPE_CHECKING:
    from bayesmachine.params import MachineParams

__all__ = ["SMTJSource", "TelegraphBank", "dwells", "flip_probabilities", "smtj_device_count"]

_GAMMA = np.uint64(0x9E3779B97F4A7C15)
_M1 = np.uint64(0xBF58476D1CE4E5B9)
_M2 = np.uint64(0x94D049BB133111EB)
_S30, _S27, _S31 = np.uint64(30), np.uint64(27), np.uint64(31)

# Stream tags: independent seed sequences for the pieces drawn from one machine seed.
_TAG_SMTJ = 0x534D544A  # "SMTJ"


def dwells(tau: np.ndarray | float, bias: np.ndarray | float) -> tuple[np.ndarray, np.ndarray]:
    """Mean dwell times (tau_0, tau_1) in clock cycles of devices with dwell ``tau`` and bias ``p``."""
    tau = np.asarray(tau, dtype=np.float64)
    p = np.asarray(bias, dtype=np.float64)
    if not (np.all(np.isfinite(tau)) and np.all(tau > 0)):
        raise ParameterError("tau (the mean dwell time, clock cycles) must be finite and > 0")
    if not np.all((p > 0) & (p < 1)):
        raise ParameterError("bias (the stationary probability of state 1) must lie in (0, 1)")
    ratio = np.sqrt(p / (1.0 - p))
    return tau / ratio, tau * ratio


def flip_probabilities(tau0: np.ndarray | float, tau1: np.ndarray | float) -> tuple[np.ndarray, np.ndarray]:
    """Per-cycle flip probabilities (P(0 -> 1), P(1 -> 0)) of the process sampled once per cycle."""
    a = 1.0 / np.asarray(tau0, dtype=np.float64)
    b = 1.0 / np.asarray(tau1, dtype=np.float64)
    s = a + b
    moved = -np.expm1(-s)  # 1 - exp(-(a + b)), accurate for long dwells
    return a / s * moved, b / s * moved


def _thresholds(p01: np.ndarray, p10: np.ndarray) -> np.ndarray:
    """(devices, 2) uint64: a device in state s flips when its next 64-bit draw is below thr[d, s]."""
    probs = np.stack([p01, p10], axis=1)
    # P < 1 always (a flip needs rate a + b < infinity), so P * 2**64 < 2**64 is exact in float64.
    return np.floor(np.ldexp(probs, 64)).astype(np.uint64)


@numba.njit(cache=True, inline="always")
def _splitmix64(x):
    z = x
    z = (z ^ (z >> _S30)) * _M1
    z = (z ^ (z >> _S27)) * _M2
    return z ^ (z >> _S31)


@numba.njit(cache=True)
def _sample(state, counter, thr, index, count, out):
    """``count`` cycles of a bank of devices. Each cycle, output j reads the bits
    ``state[index[j, k]] << k`` (the state *before* this cycle's flips), then every device
    draws its next 64-bit number and flips if it is below its state's threshold."""
    ndev = state.shape[0]
    nout, nbits = index.shape
    for t in range(count):
        for j in range(nout):
            v = 0
            for k in range(nbits):
                v |= np.int64(state[index[j, k]]) << k
            out[t, j] = v
        for d in range(ndev):  # branch-free: flips are unpredictable at short dwells
            counter[d] += _GAMMA
            state[d] ^= np.uint8(_splitmix64(counter[d]) < thr[d, state[d]])


class TelegraphBank:
    """A bank of independent SMTJ devices (random telegraph processes) sampled once per cycle.

    ``tau`` and ``bias`` are the nominal dwell (clock cycles) and stationary probability of
    state 1 (scalars or one value per device); ``spread`` the lognormal per-device scatter of
    each state's mean dwell (see the module docstring); ``seed`` (with ``stream``, to draw
    several independent banks from one seed) fixes every device's spread, initial state and
    flips.
    """

    def __init__(
        self,
        devices: int,
        tau: float | np.ndarray,
        bias: float | np.ndarray = 0.5,
        spread: float = 0.0,
        seed: int = 1,
        stream: int = 0,
    ) -> None:
        devices = as_int("devices", devices, 1)
        spread = as_real("spread", spread, 0, 1, " (log-sd of each dwell time)")
        tau0, tau1 = dwells(np.broadcast_to(tau, devices), np.broadcast_to(bias, devices))
        ss = np.random.SeedSequence([int(seed), _TAG_SMTJ, int(stream)])
        gen = np.random.Generator(np.random.PCG64(ss))
        z = gen.standard_normal((2, devices))  # drawn even at spread 0: the streams below do not move
        self.tau0 = tau0 * np.exp(spread * z[0])
        self.tau1 = tau1 * np.exp(spread * z[1])
        p01, p10 = flip_probabilities(self.tau0, self.tau1)
        self._thr = _thresholds(p01, p10)
        self._init_state = (gen.random(devices) < self.bias).astype(np.uint8)
        self._init_counter = gen.integers(0, 1 << 64, size=devices, dtype=np.uint64, endpoint=False)
        self.reset()

    @property
    def devices(self) -> int:
        return len(self.tau0)

    @property
    def bias(self) -> np.ndarray:
        """Each device's stationary probability of state 1 (after spread)."""
        return self.tau1 / (self.tau0 + self.tau1)

    @property
    def tau(self) -> np.ndarray:
        """Each device's dwell: the geometric mean of its two mean dwells (after spread)."""
        return np.sqrt(self.tau0 * self.tau1)

    def reset(self) -> None:
        """Back to the initial states: the same stream starts again."""
        self.state = self._init_state.copy()
        self._counter = self._init_counter.copy()

    def read(self, count: int, index: np.ndarray, out: np.ndarray) -> None:
        """``count`` cycles into ``out`` (count, len(index)): output j of cycle t packs the states of
        devices ``index[j, 0..k-1]`` as bits 0..k-1. Advances the bank by ``count`` cycles."""
        if count:
            _sample(self.state, self._counter, self._thr, index, count, out)

    def take(self, count: int) -> np.ndarray:
        """The next ``count`` cycles' device states, shape (count, devices), uint8."""
        count = as_int("count", count, 0)
        out = np.empty((count, self.devices), np.uint8)
        self.read(count, np.arange(self.devices, dtype=np.int64)[:, None], out)
        return out


def smtj_device_count(params: MachineParams) -> int:
    """SMTJ devices of a machine: W per operator, or W per operator column when shared by rows."""
    per = params.operators if params.smtj_share == "operator" else params.operator_columns
    return params.word_bits * per


class SMTJSource:
    """The ``"smtj"`` number source: per compute cycle, one W-bit number per operator from SMTJs.

    Operator o = r * columns + c reads bit k of its number from device ``o * W + k`` (sharing
    "operator") or ``c * W + k`` (sharing "column": every row of column c reads the same
    number). Devices are unbiased (p = 1/2) with dwell ``params.smtj_dwell`` and spread
    ``params.smtj_spread``, seeded by ``params.seed``. Implements the ``NumberSource`` protocol:
    ``take(count)`` continues the stream, two takes equal one.
    """

    def __init__(self, params: MachineParams) -> None:
        if params.rng != "smtj":
            raise ParameterError(f"SMTJSource needs rng = 'smtj', got {params.rng!r}")
        self.params = params
        self.operators = params.operators
        w, cols = params.word_bits, params.operator_columns
        self.bank = TelegraphBank(smtj_device_count(params), params.smtj_dwell, 0.5,
                                  params.smtj_spread, params.seed)
        ops = np.arange(params.operators, dtype=np.int64)
        first = ops * w if params.smtj_share == "operator" else (ops % cols) * w
        self._index = first[:, None] + np.arange(w, dtype=np.int64)[None, :]

    @property
    def devices(self) -> int:
        return self.bank.devices

    def reset(self) -> None:
        """Back to the devices' initial states (as after a hardware reset of the machine)."""
        self.bank.reset()

    def take(self, count: int) -> np.ndarray:
        """The next ``count`` compute cycles' numbers: (count, operators) uint16 in [0, 2**W)."""
        count = as_int("count", count, 0)
        out = np.empty((count, self.operators), np.uint16)
        self.bank.read(count, self._index, out)
        return out


# --- The SMTJ emulator: the same devices as digital logic (its RTL is hdl/smtj.py) ---

EMULATOR_RANDOM_BITS = 16  # flip-probability resolution of the emulator: thresholds in 1/65536


@numba.njit(cache=True, inline="always")
def _xorshift32(x):
    x ^= (x << np.uint32(13)) & np.uint32(0xFFFFFFFF)
    x ^= x >> np.uint32(17)
    x ^= (x << np.uint32(5)) & np.uint32(0xFFFFFFFF)
    return x


@numba.njit(cache=True)
def _emulate(state, x, thr, index, count, out):
    """``count`` cycles of the emulator: outputs read the states, then every device steps its
    xorshift32 generator and flips if the new value's top 16 bits are below its state's threshold."""
    ndev = state.shape[0]
    nout, nbits = index.shape
    for t in range(count):
        for j in range(nout):
            v = 0
            for k in range(nbits):
                v |= np.int64(state[index[j, k]]) << k
            out[t, j] = v
        for d in range(ndev):
            nx = _xorshift32(x[d])
            x[d] = nx
            state[d] ^= np.uint8((nx >> np.uint32(16)) < thr[d, state[d]])


class SMTJEmulatorSpec:
    """What the synthesizable SMTJ emulator holds, per device (from an ``rng = "smtj"`` machine):

    - ``thresholds`` (devices, 2): P(0 -> 1) and P(1 -> 0) of the device (``TelegraphBank`` of
      the same parameters and seed, spread included), rounded to 16 bits;
    - ``init_state``: its initial state (as the bank's); ``init_x``: its xorshift32 seed (non-zero);
    - ``index`` (operators, W): the device of each bit of each operator's number (as ``SMTJSource``).
    """

    def __init__(self, params: MachineParams) -> None:
        source = SMTJSource(params)
        bank = source.bank
        p01, p10 = flip_probabilities(bank.tau0, bank.tau1)
        scale = 1 << EMULATOR_RANDOM_BITS
        thr = np.rint(np.stack([p01, p10], axis=1) * scale)
        # A flip probability that rounds to 0 would freeze the device: keep 1/65536 at least.
        self.thresholds = np.clip(thr, 1, scale - 1).astype(np.uint32)
        self.init_state = bank._init_state.copy()
        gen = np.random.Generator(np.random.PCG64(np.random.SeedSequence([params.seed, _TAG_SMTJ, 1])))
        self.init_x = gen.integers(1, 1 << 32, size=bank.devices, dtype=np.uint64).astype(np.uint32)
        self.index = source._index.copy()
        self.params = params

    @property
    def devices(self) -> int:
        return len(self.init_state)


class SMTJEmulatorTwin:
    """Per-cycle Python twin of ``hdl.smtj.SMTJEmulator``: the same numbers, bit for bit, one row
    per cycle its ``advance`` input is high. A ``NumberSource`` (two takes equal one)."""

    def __init__(self, params: MachineParams) -> None:
        self.spec = SMTJEmulatorSpec(params)
        self.operators = params.operators
        self.reset()

    def reset(self) -> None:
        self._state = self.spec.init_state.copy()
        self._x = self.spec.init_x.copy()

    def take(self, count: int) -> np.ndarray:
        out = np.empty((int(count), self.operators), np.uint16)
        if count:
            _emulate(self._state, self._x, self.spec.thresholds, self.spec.index, int(count), out)
        return out

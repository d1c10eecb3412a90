"""The machine's ports, declared once: payload layouts and the signatures of every top that carries them.

- :func:`load_layout`, :func:`result_layout`, :func:`entropy_layout`: the payloads (the
  contract's field order; ``sim.packing`` and ``sim.results`` pack and decode from them);
- :func:`load_stream`, :func:`result_stream`, :func:`pixel_stream`: the streams of those payloads
  (and of the stereo top's pixel pairs, :func:`pixel_in_layout`);
- :func:`map_layout`, :func:`map_stream`: a machine's MAPs as the front end reads its results (the
  line of MAPs of an above column, another pass's MAPs for a pass column);
- :func:`entropy_members`: ``entropy`` / ``entropy_ready``, present exactly when the random source
  is off chip (``source_kind(rng).on_chip`` is false: ``external``, ``smtj``), the one place
  that decides it;
- :class:`MachineSignature`: ``load``, ``result`` and the entropy members (``BayesianMachine``,
  ``ParallelMachines``, ``SMTJEmulatedMachine``);
- :class:`StereoSignature`: ``pixels``, ``result``, the entropy members and each declared pass's
  ``<pass>_result`` (``StereoMachine``).

Ports and word order: ``docs/architecture.md``.
"""

from __future__ import annotations

from collections.abc import Mapping

from amaranth.hdl import unsigned
from amaranth.lib import data, stream, wiring
from amaranth.lib.wiring import In, Out

from bayesmachine.checks import as_bool
from bayesmachine.params import MachineParams

__all__ = [
    "ENTROPY_PORTS", "MachineSignature", "StereoSignature", "beat_words", "entropy_layout", "entropy_members",
    "load_layout", "load_stream", "map_layout", "map_stream", "pixel_in_layout", "pixel_stream",
    "result_layout", "result_stream",
]

ENTROPY_PORTS = ("entropy", "entropy_ready")  # the members of an off-chip source, see entropy_members


def _check_params(params: object, who: str) -> MachineParams:
    if not isinstance(params, MachineParams):
        raise TypeError(f"{who} takes a MachineParams, not {type(params).__name__}")
    return params


def load_layout(params: MachineParams) -> data.ArrayLayout | data.StructLayout:
    """One beat of the load stream: ``words_per_beat`` likelihood-memory words of W + 1 bits.

    With a neighbour prior (``prior = "neighbour"``) the beat is a struct: ``words`` (those lanes,
    from bit 0, so the words sit where they sit in every other machine) and ``line_start`` (the
    pixel has no left neighbour; the machine reads it with the pixel's last beat)."""
    words = data.ArrayLayout(unsigned(params.memory_word_width), params.words_per_beat)
    if not params.feedback_columns:
        return words
    return data.StructLayout({"words": words, "line_start": unsigned(1)})


def beat_words(params: MachineParams, payload: data.View) -> data.View:
    """The likelihood words of a load beat ``payload`` (a :func:`load_layout` view)."""
    return payload.words if params.feedback_columns else payload


def result_layout(params: MachineParams) -> data.StructLayout:
    """One pixel's result; fields in this order from bit 0 (the contract's order)."""
    return data.StructLayout({
        "map": unsigned(params.map_width),
        "nomatch": unsigned(1),
        "timeout": unsigned(1),
        "cycles": unsigned(params.cycle_width),
        # The overflow counters, or a log machine's weights (MachineParams.readout_max).
        "counts": data.ArrayLayout(unsigned(params.readout_max.bit_length()), params.rows),
    })


def entropy_layout(params: MachineParams) -> data.ArrayLayout:
    """One compute cycle's random numbers of an off-chip source: a W-bit number per operator and
    sample (B = ``samples_per_clock``), sample i's of operator o at element ``i * operators + o``."""
    return data.ArrayLayout(unsigned(params.word_bits), params.operators * params.samples_per_clock)


def pixel_in_layout() -> data.StructLayout:
    """One beat of the stereo top's pixel stream: a rectified pair and the frame-start marker."""
    return data.StructLayout({"left": unsigned(8), "right": unsigned(8), "first": unsigned(1)})


def pixel_stream() -> stream.Signature:
    """The stereo top's pixel stream (seen from its source): one :func:`pixel_in_layout` beat per pair."""
    return stream.Signature(pixel_in_layout())


def load_stream(params: MachineParams) -> stream.Signature:
    """The load stream (seen from its source): one :func:`load_layout` beat per handshake."""
    return stream.Signature(load_layout(params))


def result_stream(params: MachineParams) -> stream.Signature:
    """The result stream (seen from its source): one :func:`result_layout` payload per pixel."""
    return stream.Signature(result_layout(params))


def map_layout(map_width: int) -> data.StructLayout:
    """One MAP of a machine's results as the front end reads it: its row (``map``) and whether it is a
    disparity (``hit``: neither no match nor a timeout)."""
    return data.StructLayout({"map": unsigned(map_width), "hit": unsigned(1)})


def map_stream(params: MachineParams) -> stream.Signature:
    """A machine's MAPs as its results leave it (seen from the source): one :func:`map_layout` payload
    per result."""
    return stream.Signature(map_layout(_check_params(params, "map_stream").map_width))


def entropy_members(params: MachineParams) -> dict[str, wiring.Member]:
    """``entropy`` (``In(entropy_layout(params))``, sampled on compute cycles) and ``entropy_ready``
    (``Out(1)``, high on compute cycles: the numbers are consumed at the clock edge) for an
    off-chip random source; nothing for an on-chip one, nor for a machine that draws no random numbers."""
    if not params.takes_numbers:
        return {}
    return {"entropy": In(entropy_layout(params)), "entropy_ready": Out(1)}


class MachineSignature(wiring.Signature):
    """The machine's ports, as a component that computes disparities from likelihood words has them.

    Parameters
    ----------
    params : MachineParams
        The machine's parameters.
    entropy : bool
        Whether an off-chip source's numbers come in on ports (:func:`entropy_members`); False for
        a component that makes them itself (``SMTJEmulatedMachine``).

    Members
    -------
    load : ``In(load_stream(params))``
        A pixel's words in operator order, ``words_per_beat`` per beat, ``beats_per_pixel`` beats per pixel.
    result : ``Out(result_stream(params))``
        One result per pixel, in order.
    entropy, entropy_ready
        With an off-chip ``rng`` and ``entropy``: see :func:`entropy_members`.
    """

    def __init__(self, params: MachineParams, *, entropy: bool = True) -> None:
        self._params = _check_params(params, "MachineSignature")
        self._entropy = entropy = as_bool("entropy", entropy)
        members = {"load": In(load_stream(params)), "result": Out(result_stream(params))}
        if entropy:
            members |= entropy_members(params)
        super().__init__(members)

    @property
    def params(self) -> MachineParams:
        return self._params

    def __eq__(self, other: object) -> bool:
        return (type(other) is type(self) and other._params == self._params
                and other._entropy == self._entropy)

    def __hash__(self) -> int:
        return hash((type(self), self._params, self._entropy))

    def __repr__(self) -> str:
        return f"MachineSignature({self._params.fingerprint()}, entropy={self._entropy})"


class StereoSignature(wiring.Signature):
    """The stereo top's ports: pixel pairs in, the machine's results out, and each declared pass's.

    Parameters
    ----------
    params : MachineParams
        The machine's parameters (the model's own pass).
    passes : Mapping[str, MachineParams], optional
        The machine of each pass the model runs before its own, by pass name (default none).

    Members
    -------
    pixels : ``In(pixel_stream())``
        Pixel pairs in raster order, ``first`` set on a frame's first pixel.
    result : ``Out(result_stream(params))``
        One result per output pixel, in raster order of the output region.
    <pass>_result : ``Out(result_stream(passes[pass]))``
        Each declared pass's results, in raster order of its columns.
    entropy, entropy_ready
        With an off-chip ``rng``: see :func:`entropy_members`.
    """

    def __init__(self, params: MachineParams, passes: Mapping[str, MachineParams] | None = None) -> None:
        self._params = _check_params(params, "StereoSignature")
        self._passes = dict(passes or {})
        members = {"pixels": In(pixel_stream()), "result": Out(result_stream(params))}
        for name, pp in self._passes.items():
            if not isinstance(name, str) or not name.isidentifier():
                raise ValueError(f"passes: a pass's name makes its port's name, got {name!r}")
            members[f"{name}_result"] = Out(result_stream(_check_params(pp, "StereoSignature")))
        super().__init__(members | entropy_members(params))

    @property
    def params(self) -> MachineParams:
        return self._params

    @property
    def passes(self) -> dict[str, MachineParams]:
        return dict(self._passes)

    def __eq__(self, other: object) -> bool:
        return type(other) is type(self) and other._params == self._params and other._passes == self._passes

    def __hash__(self) -> int:
        return hash((type(self), self._params, tuple(self._passes.items())))

    def __repr__(self) -> str:
        passes = "".join(f", {n}={pp.fingerprint()}" for n, pp in self._passes.items())
        return f"StereoSignature({self._params.fingerprint()}{passes})"

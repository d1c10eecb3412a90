"""Per-pixel column normalization (``MachineParams.normalize``): each loaded column's number scale.

A normalized column's operators compare their words w with ``(number * m) >> W``, m the column's
largest word in the pixel: a word w fires when w * 2^W > r * m, the run on the words w * 2^W / m (the
operator matrix forms those numbers, ``operator.scaled_numbers``). :class:`ColumnScales` keeps the
scales m. Its Python twin is ``sim.model.column_scales`` (the scales of a pixel's words);
``tests/hdl/machine/test_normalize.py`` holds the component to it.
"""

from __future__ import annotations

from amaranth.hdl import Cat, Module, Mux, Value, unsigned
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out

from bayesmachine.integrators.stochastic import hides_bubble
from bayesmachine.params import MachineParams, ParameterError

from .nets import net, or_all

__all__ = ["ColumnScales", "largest"]


def largest(m: Module, name: str, values: list[Value]) -> Value:
    """The largest of ``values`` by one level of compares: every pair compared at once, the first of
    the largest picked by the AND of its compares (nets ``<name>_<i>``, ``<name>_gt_<i>_<j>``)."""
    values = [net(m, f"{name}_{i}", v) for i, v in enumerate(values)]
    gt = {(i, j): net(m, f"{name}_gt_{i}_{j}", values[i] > values[j])
          for i in range(len(values)) for j in range(i)}
    picked = []
    for i, v in enumerate(values):
        # v_i is picked if it exceeds every earlier value and is at least every later one.
        wins = Cat(*(gt[i, j] for j in range(i)), *(~gt[j, i] for j in range(i + 1, len(values))))
        picked.append(Mux(wins.all(), v, 0))
    return net(m, name, or_all(picked))


class ColumnScales(wiring.Component):
    """Each loaded column's number scale m: the largest of its words in the pixel.

    Per loaded column a register (``shadow``) keeps the largest of the shadow pixel's words so far,
    taken with each beat's handshake from the handshake's words and cleared at the swap (a beat taken
    in the swap, without the bubble, is the next pixel's first). The new maximum is the largest of the
    column's lanes in the beat (a lane that is not the column's in this beat reads 0) and the maximum
    so far, by one level of compares (:func:`largest`). So the maxima are final from the cycle the
    pixel's last beat is written on, a cycle before the earliest swap: the operator matrix's restart
    numbers take their scale from a register and no load cycle is added. The swap registers the
    shadow's scales as the active pixel's (``active``).

    Parameters
    ----------
    params : MachineParams
        The machine's parameters; ``normalize`` must be on.

    Attributes
    ----------
    words : ``In(unsigned(params.memory_word_width)).array(params.words_per_beat)``
        The words of the load beat offered (the load stream's payload).
    accept : ``In(1)``
        The beat is taken (the load handshake).
    beat : ``In(params.beats_per_pixel)``
        One-hot: the beat of its pixel that the handshake carries.
    start : ``In(1)``
        The swap: the shadow's pixel becomes the active one.
    shadow : ``Out(unsigned(params.memory_word_width)).array(params.loaded_columns)``
        Per loaded column, the largest of the shadow pixel's words taken so far (its scale once the
        pixel is complete).
    active : ``Out(unsigned(params.memory_word_width)).array(params.loaded_columns)``
        Per loaded column, the active pixel's scale (registered at the swap).
    active_next : ``Out(unsigned(params.memory_word_width)).array(params.loaded_columns)``
        The next value of ``active``.
    """

    def __init__(self, *, params: MachineParams) -> None:
        if not isinstance(params, MachineParams):
            raise TypeError(f"ColumnScales takes a MachineParams, not {type(params).__name__}")
        if not params.normalize:
            raise ParameterError("ColumnScales needs a machine with normalize on", "normalize")
        self._params = params
        word, loaded = unsigned(params.memory_word_width), params.loaded_columns
        super().__init__({
            "words": In(word).array(params.words_per_beat), "accept": In(1),
            "beat": In(params.beats_per_pixel), "start": In(1),
            "shadow": Out(word).array(loaded), "active": Out(word).array(loaded),
            "active_next": Out(word).array(loaded),
        })

    @property
    def params(self) -> MachineParams:
        return self._params

    def elaborate(self, platform: object) -> Module:
        m = Module()
        p = self._params
        loaded, per_beat = p.loaded_columns, p.words_per_beat
        for c in range(loaded):
            # Per lane, the beats in which it carries a word of column c.
            beats: dict[int, list[int]] = {}
            for b in range(p.beats_per_pixel):
                for lane in range(per_beat):
                    w = b * per_beat + lane
                    if w < p.words_per_pixel and w % loaded == c:
                        beats.setdefault(lane, []).append(b)
            lanes = [self.words[lane] if len(bs) == p.beats_per_pixel
                     else Mux(or_all([self.beat[b] for b in bs]), self.words[lane], 0)
                     for lane, bs in beats.items()]
            shadow = self.shadow[c]
            # Without the bubble a swap may take a beat (the next pixel's first).
            so_far = Mux(self.start, 0, shadow) if hides_bubble(p) else shadow
            best = largest(m, f"norm_beat_{c}", [*lanes, so_far])
            m.d.sync += shadow.eq(Mux(self.accept, best, Mux(self.start, 0, shadow)))
            m.d.comb += self.active_next[c].eq(Mux(self.start, shadow, self.active[c]))
            m.d.sync += self.active[c].eq(self.active_next[c])
        return m

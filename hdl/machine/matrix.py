"""The machine's operator matrix on its own registers: each row's AND of ``number < word``, the
stochastic bus (B bits per row, one per sample: operator o's sample i compares its word with number
``sample_points[i]`` XOR its source's number).

Built into the machine's module by :func:`operator_matrix` from ``operator.operator_bits`` and
``operator.bus_rows`` (``operator.operator_rows``, their composition, is the function the
operator test's component wraps): not a submodule, whose port copies of every word and number
would slow Amaranth's Python simulator, which also slows with hierarchy depth. The parts:

- numbers on the ``entropy`` port (an off-chip source) are compared in their cycle
  (:func:`_port_matrix`);
- an on-chip source's comparators are prefetched (:func:`_bit_registers`): ``bit_q[o]`` holds this
  compute cycle's ``number < word``, loaded in the cycle before, in a compute cycle from the next
  numbers and the same word, in a swap from the numbers the source gives after the start and the
  incoming (shadow) word; same bits as comparing in the cycle itself, but the matrix's path to the
  stop flip-flop starts at a register instead of a carry chain;
- the numbers they compare: a source's own per operator (:func:`_own_numbers`) or, shared by a
  column's rows, registered copies per group of rows (:func:`_shared_numbers`); normalized
  columns' numbers scaled by their column's scale (:func:`_normalized`);
- without the bubble, the next run's first bits, registered a cycle early (:func:`_swap_bits`).
"""

from __future__ import annotations

from amaranth.hdl import Cat, Const, Module, Signal, Value

from bayesmachine.params import MachineParams

from .nets import MachineNets, net, register_copy
from .operator import bus_rows, operator_bits, sample_bits, sample_low, scaled_numbers

__all__ = ["operator_matrix"]

Points = list[tuple[int, ...]]


def operator_matrix(m: Module, n: MachineNets, p: MachineParams, entropy: Value | None) -> None:
    """The operator matrix: ``n.row``, this compute cycle's stochastic bus, and for an on-chip source
    ``n.next_bits`` and ``n.swap_bits`` (the bits of the next compute cycle and of a swap), from the
    active memory and the random source (``n.source``, or with none the numbers on ``entropy``)."""
    n.row = Signal(p.rows * p.samples_per_clock, name="row")
    if n.source is None:
        _port_matrix(m, n, p, entropy)
        return
    points = list(n.source.sample_points)
    swap_at = list(n.source.swap_points) if n.hidden else points
    numbers = _shared_numbers if n.source.shared else _own_numbers
    next_numbers, restart = numbers(m, n, p, points, swap_at)
    n.next_bits = _compare(m, n, p, next_numbers, n.active, "next")
    n.swap_bits = _swap_bits(m, n, p, restart, swap_at)
    _bit_registers(m, n, p)


def _port_matrix(m: Module, n: MachineNets, p: MachineParams, entropy: Value) -> None:
    """Numbers from a port arrive in their cycle and are compared then (sample i's at i * operators)."""
    ops, cols, samples = p.operators, p.operator_columns, p.samples_per_clock
    numbers = [entropy[i * ops + o] for i in range(samples) for o in range(ops)]
    scaled = [scaled_numbers(x, n.scale_active[j % ops % cols], (0,))[0] if p.normalize else x
              for j, x in enumerate(numbers)]
    bits = [Cat(scaled[i * ops + o] < n.active[o] for i in range(samples)) for o in range(ops)]
    m.d.comb += n.row.eq(bus_rows(bits, p.rows, cols, samples))


def _compare(m: Module, n: MachineNets, p: MachineParams, numbers: list, words: list[Value], kind: str,
             at: Points | None = None) -> list[Value]:
    """Per operator, its B bits (``at``: other points per number entry) from its number, or from its
    list of normalized numbers, one per point (compared as they are); with B samples nets of their own
    (``<kind>_bits_<r>_<c>``, read in several places)."""
    ops, cols, samples = p.operators, p.operator_columns, p.samples_per_clock
    index = n.source.operator_numbers
    at = list(n.source.sample_points) if at is None else at
    if samples == 1 and not any(isinstance(x, list) for x in numbers):
        if not any(a != (0,) for a in at):
            return operator_bits(numbers, words, range(ops))
        return [sample_bits(numbers[o], words[o], at[index[o]]) for o in range(ops)]
    out = []
    for o in range(ops):
        name = f"{o // cols}_{o % cols}"
        if isinstance(numbers[o], list):
            bits = Cat(*(x < words[o] for x in numbers[o]))
        else:
            low = net(m, f"{kind}_low_{name}", sample_low(numbers[o], words[o], at[index[o]]))
            bits = sample_bits(numbers[o], words[o], at[index[o]], low=low)
        out.append(net(m, f"{kind}_bits_{name}", bits) if samples > 1 else bits)
    return out


def _normalized(m: Module, p: MachineParams, name: str, numbers: list[Value], scales: list[Value],
                at: Points) -> list:
    """``numbers`` (one per column, or per operator for a source of its own) as they are, or, where
    ``scales`` gives a scale m below 2^W or a signal (a normalized column: ``normalize``), as the list
    of ``((number ^ point) * m) >> W`` per point of ``at`` (:func:`scaled_numbers`, nets named
    ``<name>_<i>_<j>``). A feedback column's scale is the constant 2^W: kept as it is."""
    out: list = []
    for i, number in enumerate(numbers):
        scale = scales[i] if scales else None
        if scale is None or (isinstance(scale, Const) and scale.value == p.word_one):
            out.append(number)
            continue

        def part_net(part: str, value: Value, i: int = i) -> Value:
            return net(m, f"{name}_{i}_{part}", value)

        scaled = scaled_numbers(number, scale, at[i], part_net)
        out.append([part_net(str(j), x) for j, x in enumerate(scaled)])
    return out


def _own_numbers(m: Module, n: MachineNets, p: MachineParams, points: Points,
                 swap_at: Points) -> tuple[list, list]:
    """A source whose numbers each feed one operator: its next and restart numbers per operator
    (normalized by the active and the shadow pixel's scales)."""
    ops, cols = p.operators, p.operator_columns
    index = n.source.operator_numbers

    def spread(values: list) -> list:  # per number entry -> per operator
        return [values[index[o]] for o in range(ops)]

    def by_column(scales: list[Value]) -> list[Value]:
        return [scales[o % cols] for o in range(ops)] if scales else []

    next_numbers = _normalized(m, p, "next_number_norm", spread(list(n.source.next_numbers)),
                               by_column(n.scale_active), spread(points))
    restart = _normalized(m, p, "restart_number_norm", spread(list(n.source.restart_numbers)),
                          by_column(n.scale_shadow), spread(swap_at))
    return next_numbers, restart


def _shared_numbers(m: Module, n: MachineNets, p: MachineParams, points: Points,
                    swap_at: Points) -> tuple[list, list]:
    """A number shared by a column's rows would reach all its comparators from one net: each group of
    rows gets a registered copy of the column's next numbers, loaded every clock from
    ``following_numbers`` (so equal to ``next_numbers`` in every cycle), and one of its restart
    numbers, loaded from ``following_restart_numbers`` (equal to ``restart_numbers``). The flow keeps
    these ``_rep`` registers apart too. Normalized columns copy their scaled numbers (one per point),
    formed once per source copy: the next numbers from the next cycle's scales (the active pixel's,
    or the shadow's at a swap), the restart numbers from the shadow's maxima registers, final from the
    cycle the pixel's last beat is written on (taken with its handshake), so before any swap."""
    index = n.source.operator_numbers

    def group_copies(name: str, attr: str, scales: list[Value], at: Points) -> list:
        copies, per_source = [], {}
        for g in range(n.groups):
            k = g // n.groups_per_source
            if k not in per_source:
                following = list(getattr(n.sources[k], attr))
                per_source[k] = _normalized(m, p, f"{name}_norm{k}", following, scales, at)
            copies.append([register_copy(m, f"{name}_rep{g}_{i}", x) for i, x in enumerate(per_source[k])])
        return [copies[o // p.operator_columns // n.rows_per_group][index[o]] for o in range(p.operators)]

    return (group_copies("next_number", "following_numbers", n.scale_active_n, points),
            group_copies("restart_number", "following_restart_numbers", n.scale_shadow, swap_at))


def _swap_bits(m: Module, n: MachineNets, p: MachineParams, restart: list, swap_at: Points) -> list[Value]:
    """Per operator, the bits a swap loads into ``bit_q``: the restart numbers against the incoming words.

    Without the bubble (``hides_bubble``, "Timing" in docs/architecture.md) the swap is the next run's
    first compute cycle. Its bits (the restart numbers against the shadow words) are registered every
    cycle in ``first_bit`` and drive ``n.first_row`` in the swap; the swap loads ``bit_q`` with the
    run's second bits, the restart numbers XOR a block's second cycle's points against the shadow
    words, which the swap is still reading. Both come from one comparator of the low bits
    (``sample_bits``: for B = 1 the points 0 and V_0 = 2^(W-1), a comparator of the low W - 1 bits)."""
    if not n.hidden:
        return _compare(m, n, p, restart, n.incoming, "swap")
    cols, samples = p.operator_columns, p.samples_per_clock
    pair = _compare(m, n, p, restart, n.incoming, "swap", swap_at)
    first_bits, swap_bits = [], []
    for o in range(p.operators):
        first_bit = Signal(samples, name=f"first_bit_{o // cols}_{o % cols}")
        m.d.sync += first_bit.eq(pair[o][:samples])
        first_bits.append(first_bit)
        swap_bits.append(pair[o][samples:])
    n.first_row = bus_rows(first_bits, p.rows, cols, samples)
    return swap_bits


def _bit_registers(m: Module, n: MachineNets, p: MachineParams) -> None:
    """The prefetched comparator bits ``bit_<r>_<c>`` and the stochastic bus ``n.row`` they form."""
    cols, samples = p.operator_columns, p.samples_per_clock
    bits = []
    for o in range(p.operators):
        g = o // cols // n.rows_per_group
        bit_q = Signal(samples, name=f"bit_{o // cols}_{o % cols}")
        # A swap first: with the bubble it never coincides with a compute cycle; without, the swap is
        # also a compute cycle (the next run's first).
        with m.If(n.start_rep[g]):
            m.d.sync += bit_q.eq(n.swap_bits[o])
        with m.Elif(n.compute_rep[g]):
            m.d.sync += bit_q.eq(n.next_bits[o])
        bits.append(bit_q)
    m.d.comb += n.row.eq(bus_rows(bits, p.rows, cols, samples))

"""``BoardCore``: the board's design without its pins and clock: a UART, the framed protocol
(:mod:`.protocol`) and the camera-fed ``StereoMachine``. The ULX3S top (:mod:`.ulx3s`) puts it on the
board's FTDI pins behind a PLL; ``board simulate`` runs it under Verilator with its UART pins
bridged to a pseudo-terminal. Its twin is :class:`~.twin.BoardTwin`.

Data path: ``rx`` -> :class:`~.uart.UARTRx` -> receive FIFO (``2**rx_fifo_log2`` bytes, block RAM) ->
parser (hunts for a header, checks its CRC-16; streams a frame's pixel pairs into the
StereoMachine, CRC-32 over them) ; StereoMachine results -> result records -> ``tx``, with the
control records (``H`` after reset, ``I``, ``S``, ``E``, ``X``) between whole records.

The StereoMachine is reset at every frame the board accepts (and when a frame is abandoned), so a
frame's results are the model's from reset whatever came before. The receive timeout
(``timeout_bits`` bit times) counts only while the board waits for the host: mid-frame, nothing
in the receive FIFO, every output pixel fed already answered and nothing being sent; then the
frame ends with status TIMEOUT (a dropped byte leaves the board one byte short for ever).
"""

from __future__ import annotations

from amaranth.hdl import Array, C, Cat, Const, Module, Mux, ResetInserter, Signal, Value
from amaranth.lib import fifo, wiring
from amaranth.lib.wiring import In, Out

from bayesmachine.hdl.signatures import result_layout
from bayesmachine.likelihood import ModelParams
from bayesmachine.params import MachineParams, ParameterError
from bayesmachine.sources import source_kind

from . import protocol as pr
from .uart import UARTRx, UARTTx, check_clocks_per_bit

__all__ = ["BoardCore", "board_signature", "check_board", "check_core_options", "crc16_byte", "crc32_byte"]

DEFAULT_TIMEOUT_BITS = 300_000  # 0.1 s at 3 Mbaud


def _crc_matrix(width: int, step) -> list[tuple[list[int], list[int]]]:  # noqa: ANN001
    """Each bit of a CRC register after one byte, as the register bits and byte bits it XORs (a
    CRC is linear): ``step`` runs the bitwise algorithm on sets of bit names."""
    crc = [frozenset({("c", i)}) for i in range(width)]
    data = [frozenset({("d", i)}) for i in range(8)]
    crc = step(crc, data)
    return [(sorted(i for k, i in bit if k == "c"), sorted(i for k, i in bit if k == "d")) for bit in crc]


def _crc16_step(crc, data):  # noqa: ANN001, ANN202 - MSB first, polynomial 0x1021
    for i in range(8):
        top = crc[15] ^ data[7 - i]
        crc = [
            (top if (0x1021 >> j) & 1 else frozenset()) ^ (crc[j - 1] if j else frozenset())
            for j in range(16)
        ]
    return crc


def _crc32_step(crc, data):  # noqa: ANN001, ANN202 - reflected, polynomial 0xEDB88320
    for i in range(8):
        low = crc[0] ^ data[i]
        crc = [
            (crc[j + 1] if j < 31 else frozenset()) ^ (low if (0xEDB88320 >> j) & 1 else frozenset())
            for j in range(32)
        ]
    return crc


_CRC16 = _crc_matrix(16, _crc16_step)
_CRC32 = _crc_matrix(32, _crc32_step)


def _apply(matrix: list[tuple[list[int], list[int]]], crc: Value, byte: Value) -> Value:
    return Cat(*(Cat(*(crc[i] for i in c), *(byte[i] for i in d)).xor() for c, d in matrix))


def crc16_byte(crc: Value, byte: Value) -> Value:
    """CRC-16/CCITT-FALSE (polynomial 0x1021, MSB first) after one more byte: an XOR per bit."""
    return _apply(_CRC16, crc, byte)


def crc32_byte(crc: Value, byte: Value) -> Value:
    """The reflected CRC-32 register (zlib's polynomial 0xEDB88320) after one more byte."""
    return _apply(_CRC32, crc, byte)


def check_board(params: MachineParams, model: ModelParams, width: int) -> None:
    """``ParameterError`` naming the problem unless a board top can carry this StereoMachine."""
    from bayesmachine.hdl.frontend.stereo import check_stereo_machine

    if model.lr:  # the StereoMachine runs it (issue 22), the board's link carries no right pass
        raise ParameterError(
            f"--model {model.name}: the board's on-chip front end computes the paper and census models (its "
            f"link does not carry census-lr's right pass); run --model {model.name} with --engine verilator "
            "--feed pixels, or --feed words")
    check_stereo_machine(params, model, width)
    if not source_kind(params.rng).on_chip:
        raise ParameterError(
            f"--rng {params.rng}: a board needs an on-chip random source (its numbers "
            "would have to come from outside the board)"
        )


def check_core_options(clocks_per_bit: int, rx_fifo_log2: int, timeout_bits: int) -> None:
    """TypeError/ValueError naming the option unless ``BoardCore`` takes these."""
    check_clocks_per_bit(clocks_per_bit)
    for name, value, lo, hi in (
        ("rx_fifo_log2", rx_fifo_log2, 4, 15),
        ("timeout_bits", timeout_bits, 16, 1 << 30),
    ):
        if isinstance(value, bool) or not isinstance(value, int):
            raise TypeError(f"{name} must be an integer, not {type(value).__name__}")
        if not lo <= value <= hi:
            raise ValueError(f"{name} must be in [{lo}, {hi}], got {value}")


def board_signature() -> wiring.Signature:
    """The ports of :class:`BoardCore` (and of every board's core): the UART's pins, LEDs, busy."""
    return wiring.Signature({"rx": In(1, init=1), "tx": Out(1, init=1), "leds": Out(8), "busy": Out(1)})


class BoardCore(wiring.Component):
    """The board's design behind its UART pins (see the module text).

    Parameters
    ----------
    params : MachineParams
        The machine (``words_per_beat`` a multiple of the operator columns, an on-chip random source).
    model : ModelParams
        The disparity model (paper).
    width : int
        Pixels per line of every frame (the StereoMachine's line buffers are built for it).
    clocks_per_bit : int
        The clock over the baud rate (4 .. 65536).
    rx_fifo_log2 : int
        The receive FIFO holds ``2**rx_fifo_log2`` bytes (4 .. 15).
    timeout_bits : int
        The receive timeout, in bit times.

    Attributes
    ----------
    rx : ``In(1)``
        Serial data from the host (idle high).
    tx : ``Out(1)``
        Serial data to the host (idle high).
    leds : ``Out(8)``
        0: a frame is in progress; 1: the last frame or header failed; 2, 3: toggle at each byte
        received, sent; 4: the receive FIFO overflowed during the last frame.
    busy : ``Out(1)``
        Anything in flight (a simulation may sleep while it is low and no byte comes in).
    """

    def __init__(
        self,
        *,
        params: MachineParams,
        model: ModelParams,
        width: int,
        clocks_per_bit: int,
        rx_fifo_log2: int = 12,
        timeout_bits: int = DEFAULT_TIMEOUT_BITS,
    ) -> None:
        check_board(params, model, width)
        check_core_options(clocks_per_bit, rx_fifo_log2, timeout_bits)
        self._params, self._model, self._width = params, model, width
        self._cpb, self._fifo_log2, self._timeout_bits = clocks_per_bit, rx_fifo_log2, timeout_bits
        self._fingerprint = pr.board_fingerprint(params.to_dict(), model.to_dict(), width)
        super().__init__(board_signature())

    @property
    def params(self) -> MachineParams:
        return self._params

    @property
    def model(self) -> ModelParams:
        return self._model

    @property
    def width(self) -> int:
        return self._width

    @property
    def clocks_per_bit(self) -> int:
        return self._cpb

    @property
    def rx_fifo_log2(self) -> int:
        return self._fifo_log2

    @property
    def timeout_bits(self) -> int:
        return self._timeout_bits

    @property
    def fingerprint(self) -> int:
        return self._fingerprint

    def elaborate(self, platform: object) -> Module:  # noqa: C901 - one FSM, read top to bottom
        from bayesmachine.hdl.frontend.stereo import StereoMachine

        m = Module()
        p, width, dmax = self._params, self._width, self._model.dmax
        edge = 2 * self._model.margin  # the model's output region: every window inside the image
        out_cols = width - edge - dmax

        m.submodules.uart_rx = urx = UARTRx(clocks_per_bit=self._cpb)
        m.submodules.uart_tx = utx = UARTTx(clocks_per_bit=self._cpb)
        m.submodules.rx_fifo = rxf = fifo.SyncFIFOBuffered(width=8, depth=1 << self._fifo_log2)
        m.d.comb += [urx.rx.eq(self.rx), self.tx.eq(utx.tx)]
        m.d.comb += [rxf.w_stream.payload.eq(urx.data.payload), rxf.w_stream.valid.eq(urx.data.valid)]
        overflow = Signal()
        byte = rxf.r_stream.payload
        have = rxf.r_stream.valid
        pop = Signal()
        m.d.comb += rxf.r_stream.ready.eq(pop)

        # The StereoMachine's reset, registered: it reaches every flip-flop of the machine, so it
        # must not start from the parser's header checks (the first place and route's critical path).
        sm_rst = Signal()
        m.d.sync += sm_rst.eq(0)
        stereo = StereoMachine(params=p, model=self._model, width=width)
        m.submodules.stereo = ResetInserter({"sync": sm_rst})(stereo)

        # --- Control records: loaded whole by the parser, sent with their CRC-16 computed on the way.
        ctl_pending = Signal()
        ctl_type = Signal(8)
        ctl_seq = Signal(8)
        ctl_payload = Signal(8 * pr.PAYLOAD_BYTES)
        ctl_idx = Signal(range(pr.RECORD_BYTES))
        ctl_crc = Signal(16, init=0xFFFF)
        ctl_bytes = Array(
            [
                C(pr.SYNC[0], 8),
                C(pr.SYNC[1], 8),
                ctl_type,
                ctl_seq,
                *(ctl_payload[8 * i : 8 * i + 8] for i in range(pr.PAYLOAD_BYTES)),
                ctl_crc[:8],
                ctl_crc[8:],
            ]
        )

        # --- Result records: one StereoMachine result captured, sent field by field.
        fields = Signal(2)
        res_pending = Signal()
        res = Signal(result_layout(p))
        fmt = pr.ResultFormat.of(p, pr.FIELDS_ALL)

        def chunks(value: Value, nbytes: int) -> list[Value]:
            v = value.as_unsigned()
            v = Cat(v, C(0, nbytes * 8 - len(v))) if len(v) < nbytes * 8 else v
            return [v[8 * i : 8 * i + 8] for i in range(nbytes)]

        head = [C(pr.RESULT_TAG, 8), *chunks(Cat(res.map, res.nomatch, res.timeout), fmt.head_bytes)]
        counts = [b for i in range(p.rows) for b in chunks(res.counts[i], fmt.count_bytes)]
        cycles = chunks(res.cycles, fmt.cycle_bytes)
        res_bytes = Array([*head, *counts, *cycles])
        end_head, end_counts, last = len(head) - 1, len(head) + len(counts) - 1, len(res_bytes) - 1
        res_idx = Signal(range(len(res_bytes)))

        # --- The transmitter's owner: a whole record at a time, into a byte register in front of the
        # UART (the record multiplexers and the CRC's XORs stay off the UART's path).
        owner_ctl = Signal()
        owner_res = Signal()
        tx_valid = Signal()
        tx_byte = Signal(8)
        m.d.comb += [utx.data.valid.eq(tx_valid), utx.data.payload.eq(tx_byte)]
        with m.If(utx.data.ready):
            m.d.sync += tx_valid.eq(0)
        load = Signal()  # the owner's next byte goes into the register
        m.d.comb += load.eq((~tx_valid | utx.data.ready) & (owner_ctl | owner_res))
        with m.If(~owner_ctl & ~owner_res):
            with m.If(ctl_pending):
                m.d.sync += owner_ctl.eq(1)
            with m.Elif(res_pending):
                m.d.sync += owner_res.eq(1)
        with m.If(load):
            m.d.sync += [tx_valid.eq(1), tx_byte.eq(Mux(owner_ctl, ctl_bytes[ctl_idx], res_bytes[res_idx]))]

        with m.If(owner_ctl & load):
            with m.If(ctl_idx < pr.RECORD_BYTES - 2):
                m.d.sync += ctl_crc.eq(crc16_byte(ctl_crc, ctl_bytes[ctl_idx]))
            with m.If(ctl_idx == pr.RECORD_BYTES - 1):
                m.d.sync += [ctl_idx.eq(0), ctl_pending.eq(0), owner_ctl.eq(0), ctl_crc.eq(0xFFFF)]
            with m.Else():
                m.d.sync += ctl_idx.eq(ctl_idx + 1)

        results_sent = Signal(32)
        res_crc = Signal(32, init=0xFFFFFFFF)
        # The results' CRC-32 from the byte register, the cycle after its load (it holds the byte then).
        crc_pending = Signal()
        m.d.sync += crc_pending.eq(owner_res & load)
        with m.If(crc_pending):
            m.d.sync += res_crc.eq(crc32_byte(res_crc, tx_byte))
        with m.If(owner_res & load):
            done = Signal()
            nxt = Signal.like(res_idx)
            with m.If(res_idx == end_head):
                m.d.comb += [
                    nxt.eq(Mux(fields[0], end_head + 1, end_counts + 1)),
                    done.eq(~fields[0] & ~fields[1]),
                ]
            with m.Elif(res_idx == end_counts):
                m.d.comb += [nxt.eq(end_counts + 1), done.eq(~fields[1])]
            with m.Elif(res_idx == last):
                m.d.comb += done.eq(1)
            with m.Else():
                m.d.comb += nxt.eq(res_idx + 1)
            with m.If(done):
                m.d.sync += [
                    res_idx.eq(0),
                    res_pending.eq(0),
                    owner_res.eq(0),
                    results_sent.eq(results_sent + 1),
                ]
            with m.Else():
                m.d.sync += res_idx.eq(nxt)

        aborting = Signal()
        results_taken = Signal(32)
        m.d.comb += stereo.result.ready.eq(~res_pending & ~aborting & ~sm_rst)
        with m.If(stereo.result.valid & stereo.result.ready):
            m.d.sync += [
                res.eq(stereo.result.payload),
                res_pending.eq(1),
                results_taken.eq(results_taken + 1),
            ]

        # --- The parser.
        hdr = Signal(8 * (pr.RECORD_BYTES - 2))  # the bytes after the sync, first at bit 0
        hdr_count = Signal(range(pr.RECORD_BYTES))
        rx_crc = Signal(16)
        h_type, h_seq = hdr[0:8], hdr[8:16]
        h_payload = hdr[16 : 16 + 8 * pr.PAYLOAD_BYTES]
        h_crc = hdr[16 + 8 * pr.PAYLOAD_BYTES :]
        h_fields, h_width, h_height = h_payload[0:8], h_payload[8:24], h_payload[24:40]

        seq = Signal(8)
        height = Signal(16)
        expected = Signal(32)
        mul_a = Signal(16)
        mul_add = Signal(32)
        col = Signal(range(width))
        line = Signal(16)
        left = Signal(8)
        right = Signal(8)
        pix_crc = Signal(32)
        got_crc = Signal(32)
        trailer = Signal(range(4))
        fed_outputs = Signal(32)
        silence = Signal(range(self._timeout_bits * self._cpb + 1))
        info = Const(
            int.from_bytes(pr.info_payload(width, p.rows, self._fifo_log2, self._fingerprint), "little"),
            8 * pr.PAYLOAD_BYTES,
        )
        error_led = Signal()
        in_frame = Signal()

        def emit(kind: int, seq_value: Value, payload: Value) -> None:
            payload = payload.as_unsigned()
            m.d.sync += [
                ctl_type.eq(kind),
                ctl_seq.eq(seq_value),
                ctl_pending.eq(1),
                ctl_payload.eq(Cat(payload, C(0, 8 * pr.PAYLOAD_BYTES - len(payload)))),
            ]

        def end_record(status: Value) -> None:
            emit(pr.END, seq, Cat(status.as_unsigned()[:8], results_sent, ~res_crc))
            m.d.sync += error_led.eq(status != pr.STATUS_OK)

        # The receive timeout: only while the board waits on the host (see the module text).
        waiting = Signal()  # in a state that waits for the host's bytes
        timed_out = Signal()
        quiet = (
            waiting
            & ~have
            & (fed_outputs == results_taken)
            & ~res_pending
            & ~ctl_pending
            & ~owner_ctl
            & ~owner_res
            & ~utx.active
            & ~tx_valid
            & ~urx.active
        )
        m.d.comb += timed_out.eq(quiet & (silence == self._timeout_bits * self._cpb - 1))
        m.d.sync += silence.eq(Mux(quiet & ~timed_out, silence + 1, 0))
        with m.FSM(init="BOOT"):
            with m.State("BOOT"):
                with m.If(~ctl_pending):
                    emit(pr.HELLO, C(0, 8), info)
                    m.next = "SYNC0"
            with m.State("SYNC0"):
                with m.If(have):
                    m.d.comb += pop.eq(1)
                    with m.If(byte == pr.SYNC[0]):
                        m.d.sync += rx_crc.eq(crc16_byte(C(0xFFFF, 16), byte))
                        m.next = "SYNC1"
            with m.State("SYNC1"):
                with m.If(have):
                    m.d.comb += pop.eq(1)
                    with m.If(byte == pr.SYNC[1]):
                        m.d.sync += [rx_crc.eq(crc16_byte(rx_crc, byte)), hdr_count.eq(0)]
                        m.next = "HEADER"
                    with m.Elif(byte == pr.SYNC[0]):
                        m.d.sync += rx_crc.eq(crc16_byte(C(0xFFFF, 16), byte))
                    with m.Else():
                        m.next = "SYNC0"
            with m.State("HEADER"):
                with m.If(have):
                    m.d.comb += pop.eq(1)
                    m.d.sync += [hdr.eq(Cat(hdr[8:], byte)), hdr_count.eq(hdr_count + 1)]
                    with m.If(hdr_count < pr.RECORD_BYTES - 4):
                        m.d.sync += rx_crc.eq(crc16_byte(rx_crc, byte))
                    with m.If(hdr_count == pr.RECORD_BYTES - 3):
                        m.next = "CHECK"
            with m.State("CHECK"):
                with m.If(~ctl_pending):
                    with m.If(rx_crc != h_crc):
                        emit(pr.ERROR, h_seq, C(pr.ERR_HEADER, 8))
                        m.d.sync += error_led.eq(1)
                        m.next = "SYNC0"
                    with m.Elif(h_type == pr.INFO):
                        emit(pr.INFO, h_seq, info)
                        m.next = "SYNC0"
                    with m.Elif(h_type == pr.FRAME):
                        with m.If((h_width == width) & (h_height >= edge + 1)):
                            m.d.sync += sm_rst.eq(1)
                            m.d.sync += [
                                seq.eq(h_seq),
                                fields.eq(h_fields[:2]),
                                height.eq(h_height),
                                mul_a.eq(h_height - edge),
                                mul_add.eq(out_cols),
                                expected.eq(0),
                                col.eq(0),
                                line.eq(0),
                                pix_crc.eq(0xFFFFFFFF),
                                res_crc.eq(0xFFFFFFFF),
                                results_sent.eq(0),
                                results_taken.eq(0),
                                fed_outputs.eq(0),
                                trailer.eq(0),
                                overflow.eq(0),
                            ]
                            m.next = "COUNT"
                        with m.Else():
                            emit(pr.ERROR, h_seq, Cat(C(pr.ERR_SIZE, 8), C(width, 16)))
                            m.d.sync += error_led.eq(1)
                            m.next = "SYNC0"
                    with m.Else():
                        emit(pr.ERROR, h_seq, Cat(C(pr.ERR_TYPE, 8), h_type, C(0, 8)))
                        m.d.sync += error_led.eq(1)
                        m.next = "SYNC0"
            with m.State("COUNT"):  # the results to come, (height - edge) x out_cols, by shift and add
                m.d.comb += in_frame.eq(1)
                with m.If(mul_a == 0):
                    with m.If(~ctl_pending):
                        emit(pr.START, seq, Cat(fields, C(0, 6), C(width, 16), height, expected))
                        m.next = "LEFT"
                with m.Else():
                    with m.If(mul_a[0]):
                        m.d.sync += expected.eq(expected + mul_add)
                    m.d.sync += [mul_a.eq(mul_a >> 1), mul_add.eq(mul_add << 1)]
            with m.State("LEFT"):
                m.d.comb += [in_frame.eq(1), waiting.eq(1)]
                with m.If(have):
                    m.d.comb += pop.eq(1)
                    m.d.sync += [left.eq(byte), pix_crc.eq(crc32_byte(pix_crc, byte))]
                    m.next = "RIGHT"
                with m.If(timed_out):
                    m.next = "ABORT"
            with m.State("RIGHT"):
                m.d.comb += [in_frame.eq(1), waiting.eq(1)]
                with m.If(have):
                    m.d.comb += pop.eq(1)
                    m.d.sync += [right.eq(byte), pix_crc.eq(crc32_byte(pix_crc, byte))]
                    m.next = "PUSH"
                with m.If(timed_out):
                    m.next = "ABORT"
            with m.State("PUSH"):
                m.d.comb += in_frame.eq(1)
                pix = stereo.pixels
                m.d.comb += [
                    pix.valid.eq(1),
                    pix.payload.left.eq(left),
                    pix.payload.right.eq(right),
                    pix.payload.first.eq((col == 0) & (line == 0)),
                ]
                with m.If(pix.ready):
                    with m.If((line >= edge) & (col >= dmax + edge)):
                        m.d.sync += fed_outputs.eq(fed_outputs + 1)
                    with m.If(col == width - 1):
                        m.d.sync += [col.eq(0), line.eq(line + 1)]
                        with m.If(line == height - 1):
                            m.next = "TRAILER"
                        with m.Else():
                            m.next = "LEFT"
                    with m.Else():
                        m.d.sync += col.eq(col + 1)
                        m.next = "LEFT"
            with m.State("TRAILER"):
                m.d.comb += [in_frame.eq(1), waiting.eq(1)]
                with m.If(have):
                    m.d.comb += pop.eq(1)
                    m.d.sync += [got_crc.eq(Cat(got_crc[8:], byte)), trailer.eq(trailer + 1)]
                    with m.If(trailer == 3):
                        m.next = "DRAIN"
                with m.If(timed_out):
                    m.next = "ABORT"
            with m.State("DRAIN"):
                m.d.comb += in_frame.eq(1)
                with m.If(~ctl_pending & ~crc_pending & (results_sent == expected)):
                    status = Signal(8)
                    with m.If(overflow):
                        m.d.comb += status.eq(pr.STATUS_OVERFLOW)
                    with m.Elif(got_crc != ~pix_crc):
                        m.d.comb += status.eq(pr.STATUS_CHECKSUM)
                    with m.Else():
                        m.d.comb += status.eq(pr.STATUS_OK)
                    end_record(status)
                    m.next = "SYNC0"
            with m.State("ABORT"):
                m.d.comb += [in_frame.eq(1), aborting.eq(1)]
                with m.If(~ctl_pending & ~res_pending & ~crc_pending):
                    end_record(Mux(overflow, C(pr.STATUS_OVERFLOW, 8), C(pr.STATUS_TIMEOUT, 8)))
                    m.d.sync += sm_rst.eq(1)
                    m.next = "SYNC0"

        with m.If(urx.data.valid & ~rxf.w_stream.ready):
            m.d.sync += overflow.eq(1)

        led_rx = Signal()
        led_tx = Signal()
        with m.If(urx.data.valid):
            m.d.sync += led_rx.eq(~led_rx)
        with m.If(load):
            m.d.sync += led_tx.eq(~led_tx)
        m.d.comb += [
            self.leds.eq(Cat(in_frame, error_led, led_rx, led_tx, overflow)),
            self.busy.eq(
                in_frame
                | ctl_pending
                | res_pending
                | owner_ctl
                | owner_res
                | tx_valid
                | crc_pending
                | have
                | utx.active
                | urx.active
            ),
        ]
        return m

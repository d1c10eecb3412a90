"""``BoardCore``: the board's design without its pins and clock: a UART, the framed protocol
(:mod:`.protocol`) and the camera-fed ``StereoMachine``. The ULX3S top (:mod:`.ulx3s`) puts it on the
board's FTDI pins behind a PLL; ``board simulate`` runs it under Verilator with its UART pins
bridged to a pseudo-terminal. Its twin is :class:`~.twin.BoardTwin`.

It only wires stream components, each with its own twin and test:

- receive: ``rx`` -> :class:`~.uart.UARTRx` -> receive FIFO (``2**rx_fifo_log2`` bytes, block RAM) ->
  :class:`~.parser.HeaderParser` (the host's records) or, inside a frame,
  :class:`~.receiver.FrameReceiver` (pixel pairs into the StereoMachine, their CRC-32 checked);
- :class:`~.control.ProtocolControl`: answers the records, runs a frame from header to end record;
- transmit: :class:`~.serializer.ControlSerializer` (control records) and one
  :class:`~.serializer.ResultSerializer` per pass of the model (one result record at a time, the pass's
  tag: :func:`~.protocol.board_passes`) -> :class:`~.arbiter.TransmitArbiter` (whole records, control
  first, then the declared passes', then the own pass's) -> :class:`~.uart.UARTTx` -> ``tx``;
- :class:`~.status.ReceiveTimeout` and :class:`~.status.StatusLEDs`.

The StereoMachine is reset at every frame the board accepts (and when a frame is abandoned), so a
frame's results are the model's from reset whatever came before. The receive timeout
(``timeout_bits`` bit times) counts only while the board waits for the host: mid-frame, nothing
in the receive FIFO, every output pixel fed already answered and nothing being sent; then the
frame ends with status TIMEOUT (a dropped byte leaves the board one byte short for ever).
"""

from __future__ import annotations

from amaranth.hdl import Module, ResetInserter
from amaranth.lib import fifo, wiring
from amaranth.lib.wiring import In, Out

from bayesmachine.checks import as_int
from bayesmachine.models import ModelParams
from bayesmachine.params import MachineParams, ParameterError

from . import protocol as pr
from .arbiter import TransmitArbiter
from .control import ProtocolControl
from .parser import HeaderParser
from .protocol import BoardPass, board_passes
from .receiver import FrameReceiver
from .serializer import ControlSerializer, ResultSerializer
from .status import ReceiveTimeout, StatusLEDs
from .uart import UARTRx, UARTTx, check_clocks_per_bit

__all__ = ["RTL_MODULES", "BoardCore", "board_signature", "check_board", "check_core_options"]

# The modules that define the board's RTL beside hdl/ (the simulated board's Verilog cache keys on them).
RTL_MODULES = ("core.py", "uart.py", "protocol.py", "streams.py", "parser.py", "receiver.py", "control.py",
               "serializer.py", "arbiter.py", "status.py")

DEFAULT_TIMEOUT_BITS = 300_000  # 0.1 s at 3 Mbaud


def check_board(params: MachineParams, model: ModelParams, width: int) -> None:
    """``ParameterError`` naming the problem unless a board top can carry this StereoMachine (and every
    pass's results: :func:`~.protocol.board_passes`)."""
    from bayesmachine.hdl.frontend.stereo import check_stereo_machine

    check_stereo_machine(params, model, width)
    board_passes(params, model)
    if params.takes_numbers:
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
        as_int(name, value, lo, hi)


def board_signature() -> wiring.Signature:
    """The ports of :class:`BoardCore` (and of every board's core): the UART's pins, LEDs, busy."""
    return wiring.Signature({"rx": In(1, init=1), "tx": Out(1, init=1), "leds": Out(8), "busy": Out(1)})


class BoardCore(wiring.Component):
    """The board's design behind its UART pins (see the module text).

    Parameters
    ----------
    params : MachineParams
        The machine, of either integrator (``words_per_beat`` a multiple of the operator columns; a
        stochastic one with an on-chip random source).
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

    def elaborate(self, platform: object) -> Module:
        from bayesmachine.hdl.frontend.passes import pass_row_pixels
        from bayesmachine.hdl.frontend.stereo import StereoMachine

        m = Module()
        model, passes = self._model, board_passes(self._params, self._model)
        m.submodules.uart_rx = urx = UARTRx(clocks_per_bit=self._cpb)
        m.submodules.uart_tx = utx = UARTTx(clocks_per_bit=self._cpb)
        m.submodules.rx_fifo = rxf = fifo.SyncFIFOBuffered(width=8, depth=1 << self._fifo_log2)
        m.submodules.parser = parser = HeaderParser()
        m.submodules.receiver = receiver = FrameReceiver(width=self._width, dmax=model.dmax,
                                                         margin=model.margin)
        info = pr.info_payload(self._width, self._params.rows, self._fifo_log2, self._fingerprint)
        row = sum(pass_row_pixels(model, p.name, self._width) for p in passes)  # every pass's results
        m.submodules.control = control = ProtocolControl(width=self._width, dmax=model.dmax,
                                                         margin=model.margin, info=info, row_results=row)
        m.submodules.control_tx = control_tx = ControlSerializer()
        m.submodules.arbiter = arbiter = TransmitArbiter(results=len(passes))
        m.submodules.timeout = timeout = ReceiveTimeout(cycles=self._timeout_bits * self._cpb)
        m.submodules.leds = leds = StatusLEDs()
        # The StereoMachine's reset is the control's register: it reaches every flip-flop of the
        # machine, so it must not start from the header checks (the first place and route's critical path).
        stereo = StereoMachine(params=self._params, model=model, width=self._width)
        m.submodules.stereo = ResetInserter({"sync": control.machine_reset})(stereo)

        # Receive: the UART into the FIFO (it cannot wait: a byte the FIFO cannot take is dropped), the
        # FIFO to the parser between frames and to the frame receiver inside one.
        m.d.comb += [urx.rx.eq(self.rx), rxf.w_stream.payload.eq(urx.data.payload),
                     rxf.w_stream.valid.eq(urx.data.valid),
                     control.dropped.eq(urx.data.valid & ~rxf.w_stream.ready)]
        for sink, route in ((parser.bytes, control.hunting), (receiver.bytes, control.receiving)):
            m.d.comb += [sink.payload.eq(rxf.r_stream.payload), sink.valid.eq(rxf.r_stream.valid & route)]
        m.d.comb += rxf.r_stream.ready.eq((parser.bytes.ready & control.hunting)
                                          | (receiver.bytes.ready & control.receiving))
        wiring.connect(m, parser.headers, control.headers)
        wiring.connect(m, receiver.pixels, stereo.pixels)
        m.d.comb += [receiver.start.eq(control.frame_start), receiver.stop.eq(control.frame_stop),
                     receiver.height.eq(control.height), control.frame_done.eq(receiver.done),
                     control.crc_ok.eq(receiver.crc_ok)]

        own_tx = self._transmit(m, stereo, control, arbiter, passes)
        wiring.connect(m, control.records, control_tx.records)
        wiring.connect(m, control_tx.bytes, arbiter.control)
        wiring.connect(m, arbiter.bytes, utx.data)
        m.d.comb += self.tx.eq(utx.tx)

        # Quiet: nothing in flight but the host's bytes (see the module text); busy: anything at all.
        link_busy = (rxf.r_stream.valid | urx.active | control.records.valid | control.results_busy
                     | arbiter.busy | utx.active)
        m.d.comb += [timeout.waiting.eq(receiver.waiting),
                     timeout.busy.eq(link_busy | (receiver.fed != own_tx.taken)),
                     control.timed_out.eq(timeout.fired),
                     self.busy.eq(link_busy | control.busy)]
        m.d.comb += [leds.in_frame.eq(control.in_frame), leds.error.eq(control.error),
                     leds.overflow.eq(control.overflow), leds.received.eq(urx.data.valid),
                     leds.sent.eq(utx.data.valid & utx.data.ready), self.leds.eq(leds.leds)]
        return m

    def _transmit(self, m: Module, stereo: wiring.Component, control: ProtocolControl,
                  arbiter: TransmitArbiter, passes: tuple[BoardPass, ...]) -> ResultSerializer:
        """Each pass's results (not while a frame is given up) through a serializer of its own into the
        arbiter; the control reads their records sent in all, the XOR of their CRCs, whether any holds a
        result. Returns the own pass's serializer (the last)."""
        serializers = []
        for i, bp in enumerate(passes):
            tx = ResultSerializer(params=bp.params, tag=bp.tag)
            m.submodules[f"result_tx{'' if bp.tag == pr.RESULT_TAG else '_' + bp.name}"] = tx
            port = stereo.result if bp.tag == pr.RESULT_TAG else getattr(stereo, f"{bp.name}_result")
            m.d.comb += [tx.results.payload.eq(port.payload),
                         tx.results.valid.eq(port.valid & control.take_results),
                         port.ready.eq(tx.results.ready & control.take_results),
                         tx.fields.eq(control.fields), tx.clear.eq(control.clear_results)]
            wiring.connect(m, tx.bytes, arbiter.results[i])
            serializers.append(tx)
        sent, crc, busy = serializers[0].sent, serializers[0].crc, serializers[0].busy
        for tx in serializers[1:]:
            sent, crc, busy = sent + tx.sent, crc ^ tx.crc, busy | tx.busy
        m.d.comb += [control.results_sent.eq(sent), control.results_crc.eq(crc),
                     control.results_busy.eq(busy)]
        return serializers[-1]

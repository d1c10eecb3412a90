"""Boards: the camera-fed StereoMachine on a real FPGA board behind a serial link (issue 21).

- ``protocol``: the framed serial protocol, one definition for the RTL, its twin and the host;
- ``uart``, ``core``: the UART at bit level and ``BoardCore`` (UART + protocol + StereoMachine),
  which wires the stream components ``parser``, ``receiver``, ``control``, ``serializer``,
  ``arbiter`` and ``status`` (their layouts and CRCs: ``streams``), each with its twin;
- ``twin``: ``BoardTwin``, the core's Python twin at the byte level;
- ``ulx3s``, ``build``: the ULX3S top (PLL, pins, LEDs) and ``bayesmachine board build``;
- ``simulate``: ``bayesmachine board simulate`` (the core under Verilator behind a pseudo-terminal);
- ``link``, ``engine``: the host side, ``bayesmachine run --engine board --port PORT`` (the pixel
  engine ``board``);
- ``cli``: the ``board`` subcommands. See docs/board.md.
"""

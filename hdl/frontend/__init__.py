"""The on-chip streaming front end: rectified pixel pairs in, likelihood-memory words out.

Blocks (each a ``wiring.Component`` with a Python twin its tests hold it to):

- ``linebuffer``: four image lines of the pixel pair (six with a 7x7 census) in one ``Memory``
  (block RAM): the 5-high (7-high) column of each incoming pixel.
- ``filters``: the exact integer sums m·25, gH·20, gV·20 of a 5x5 window (twin:
  ``host.features.feature_sums``).
- ``census``: the census codes of a 7x7 or 5x5 window (twin: ``host.features.census_codes``).
- ``tables``: the likelihood tables, clamped, generated from the host's own quantized tables.
- ``costs``: the right features' delay line of Dmax + 1 pixels, the |difference| of sums, the
  table look-ups (census: Hamming distance) and the words of a pixel, ``words_per_beat`` per beat, with the
  neighbour prior's above column from a line of the machine's own MAPs (twin:
  ``host.likelihoods.memory_words``).
- ``lr``: census-lr's right pass (``RightPassFeeder`` into a ``WordGenerator(right_pass=True)``) and
  the consistency column's test (``ConsistencyTest``; twins: ``bayesmachine.columns.consistency``).
- ``stereo``: ``FrontEnd`` (pixels in, load beats out) and ``StereoMachine`` (pixels in, the
  machine's results out). Timing and protocol: ``docs/frontend.md``.
"""

# Limits shared by the RTL and the command line (importing them needs no Amaranth).
MAX_WIDTH = 4096  # the line buffers hold `width` pixel pairs: 4 (or 6) lines x 16 bits each
DEFAULT_WIDTH = 640  # pixels per line of a stereo top (emit, synth --top stereo, board build) unless told
MAX_MACHINES = 16  # StereoMachine(machines=K): K machines behind one feature pipeline
DEFAULT_FIFO_PIXELS = 8  # pixels' worth of load beats between the front end and the machine

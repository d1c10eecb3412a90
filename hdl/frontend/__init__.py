"""The on-chip streaming front end: rectified pixel pairs in, likelihood-memory words out.

Blocks (each a ``wiring.Component`` with a Python twin its tests hold it to):

- ``linebuffer``: four image lines of the pixel pair (six with a 7x7 census) in one ``Memory``
  (block RAM): the 5-high (7-high) column of each incoming pixel.
- ``filters``: the exact integer sums m·25, gH·20, gV·20 of a 5x5 window (twin:
  ``host.features.feature_sums``).
- ``census``: the census codes of a 7x7 or 5x5 window (twin: ``host.features.census_codes``).
- ``tables``: the likelihood tables, clamped, generated from the host's own quantized tables.
- ``pipeline``: ``FeaturePipeline``, the line buffer and the plane filters every pass reads, with the
  position counters and flags.
- ``lanes``: one lane builder per column kind (its planes, flags, ports and words; the consistency
  column's ``ConsistencyTest``, twins: ``bayesmachine.columns.consistency``).
- ``layouts``, ``reference``: what a pass's pixels carry, and its reference image (left or right).
- ``nets``, ``words``: a pass's word generator (``WordGenerator``) on its shared pipeline: the match
  features' delay line of Dmax + 1 pixels, the lanes' costs and table look-ups, the words of a pixel,
  ``words_per_beat`` per beat (twin: ``host.likelihoods.pass_words``).
- ``passes``: the model's declared passes (census-lr's right pass): ``PassFeeder`` by reference image,
  the pipeline's pixels to every pass, each pass's MAPs to what reads them, the front end's ports.
- ``stereo``: ``FrontEnd`` (pixels in, every pass's load beats out) and ``StereoMachine`` (pixels in,
  every pass's results out). Timing and protocol: ``docs/frontend.md``.
"""

# Limits shared by the RTL and the command line (importing them needs no Amaranth).
MAX_WIDTH = 4096  # the line buffers hold `width` pixel pairs: 4 (or 6) lines x 16 bits each
DEFAULT_WIDTH = 640  # pixels per line of a stereo top (emit, synth --top stereo, board build) unless told
MAX_MACHINES = 16  # StereoMachine(machines=K): K machines behind one feature pipeline
DEFAULT_FIFO_PIXELS = 8  # pixels' worth of load beats between the front end and the machine

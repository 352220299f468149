"""Files in and out: every format the toolkit reads or writes for other tools.

The one list of formats (sag maps, Zernike lists, measured line profiles and PSF
images, FE results), each with its suffixes, reader, writer and module, is
:data:`pipeline.io.registry.FORMATS`; ``python -m pipeline.io.registry`` prints it.
The shared helpers (atomic writes, parse errors, text and CSV decoding) are in
:mod:`pipeline.io.common`.
"""

"""Pure numeric FPP code: numpy/scipy in, numpy out; no I/O, no devices."""

"""The calibration mathematics of emlogd (paper sections II–IV), numpy only, no I/O.

Must not import: drivers, emlogd, or any I/O module.
"""

"""twinfleet's agreement layer: the live runtime and the checker, side by side.

The checker's verdicts are statements about the very node code the live fleet
runs; this package checks that they describe live runs: `validate` (is a recorded
live run a path of the checker's transitions?), `replay --live` (a trace re-enacted
on the real processes) and `calibrate` (a timing model fitted from live event
logs). It is the only package allowed to import both `checker` and the live parts
of `runtime` (`tests/test_layering.py`); `checker` never imports it. The robot case
study's experiment, which measures the robots with it, is `twinfleet.robots`.
"""

"""Closing the loop: residual diagnostics, candidate effects and model selection.

``prepare`` (data.py) turns telemetry into samples with a noise level, ``identify``
(select.py) fits the baseline (model (1) of the llr-realtime paper, jumps segmented),
diagnoses the residual and adds named effects by forward selection validated on held-out
rows; model.py writes the refined model as a configuration snippet for the detectors and
report.py the report (docs/identify.md).
"""

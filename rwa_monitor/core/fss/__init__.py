"""Window diagnoser of the physics-informed FSS paper: wGLR, LS, DP assignment, SVMs.

Stages (physics-informed-fss-friction-anomalies paper, section IV): :mod:`wglr`
(changepoints), :mod:`segments` (interval least squares and rejection costs),
:mod:`assign` (dynamic programming over the switching systems and Algorithm 1),
:mod:`classify` (one SVM per anomaly); :mod:`pipeline` chains them. All arrays here are
in the paper's normalised units and sign (friction opposing motion is positive); the
pipeline converts from the telemetry's SI units and sign.
"""

"""The public Python API: names, explicit keywords, the detector protocol, README example."""

import contextlib
import inspect
import io
import re
import subprocess
import sys

import numpy as np

import rwa_monitor
from rwa_monitor.core.protocol import StreamingDetector


def test_exports_load_without_ros():
    code = ('import sys, rwa_monitor as r; [getattr(r, n) for n in r.__all__];'
            'assert "rclpy" not in sys.modules, "rclpy imported"')
    out = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr


def test_import_is_cheap():
    code = 'import sys, rwa_monitor; assert "scipy" not in sys.modules'
    assert subprocess.run([sys.executable, '-c', code]).returncode == 0


def test_constructors_show_their_parameters():
    for cls, name in ((rwa_monitor.LLRDetector, 'k_verif'),
                      (rwa_monitor.VsadcDetector, 'sigma_window'),
                      (rwa_monitor.GyroDiagnosis, 'decide_chi2'),
                      (rwa_monitor.FssDiagnoser, 'wglr_window')):
        params = inspect.signature(cls).parameters
        assert name in params
        assert all(p.kind is not p.VAR_KEYWORD for p in params.values())


def test_streaming_detectors_follow_the_protocol():
    llr = rwa_monitor.LLRDetector('rw1', window=50)
    vsadc = rwa_monitor.VsadcDetector(window=20)
    fss = rwa_monitor.FssDiagnoser(rwa_monitor.load_fss_model(), window_length=300,
                                   window_period=100)
    for det in (llr, vsadc, fss):
        assert isinstance(det, StreamingDetector)
        assert isinstance(det.counters, dict) and isinstance(det.params, dict)
        assert det.last_event is None
    rng = np.random.default_rng(3)
    t = np.arange(2000) * 0.1
    speed = 200.0 + 150.0 * np.sin(t / 20.0)
    friction = -(2e-4 + 4e-4 * (t >= 100.0)) - 5e-7 * speed + rng.normal(0, 5e-5, t.size)
    found = [e for k in range(t.size) for e in llr.update(t[k], speed[k], friction[k])]
    assert found and llr.last_event == found[-1]
    llr.reset()
    assert llr.last_event is None and llr.n_samples == 0
    diagnoses = [d for k in range(400) if (d := fss.update(t[k], speed[k], friction[k]))]
    assert len(diagnoses) == 2 and fss.last_event == diagnoses[-1]
    assert fss.counters['diagnoses'] == 2 and set(diagnoses[0].result) >= {'anomalies'}


def test_readme_example_runs_and_prints_what_it_says(repo_root):
    text = (repo_root / 'README.md').read_text()
    section = text.split('## Python API', 1)[1]
    code = re.search(r'```python\n(.*?)```', section, re.S).group(1)
    assert len(code.strip().splitlines()) <= 6
    expected = re.search(r'prints `(.*?)`', section).group(1)
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        exec(compile(code, 'README.md', 'exec'), {})
    assert out.getvalue().strip() == expected

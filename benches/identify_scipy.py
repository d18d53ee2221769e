"""The same work as `benches/identify.rs`, written the way a Python user would: scipy Butterworth
+ filtfilt (sosfiltfilt), numpy gradient, numpy lstsq, on the 1,000,000-row recording that the
Rust benchmark writes when WHEELID_BENCH_CSV is set.

    WHEELID_BENCH_CSV=/tmp/rec1e6.csv cargo bench --bench identify
    python3 benches/identify_scipy.py /tmp/rec1e6.csv

With `--once` it is the whole process a user runs (load, one identification, print), which
`benches/identify_e2e.sh` times against `wheelid identify FILE --estimator ls`.
"""
import sys
import time

import numpy as np
from scipy.signal import butter, sosfiltfilt

with open(sys.argv[1]) as f:
    meta = 0
    for line in f:
        if not line.startswith("#"):
            header = line.strip().split(",")
            break
        meta += 1
d = np.loadtxt(sys.argv[1], delimiter=",", skiprows=meta + 1)
col = {name: d[:, i] for i, name in enumerate(header)}
t, vr, wr, v, w = col["t"], col["v_ref"], col["w_ref"], col["v"], col["w"]
dt = t[1] - t[0]


def identify():
    sos = butter(4, 0.64, fs=1 / dt, output="sos")
    f = lambda x: sosfiltfilt(sos, x)
    vf, wf = f(v), f(w)
    dv, dw = np.gradient(vf, dt), np.gradient(wf, dt)
    xv = np.column_stack([dv, f(-w * w), vf])
    xw = np.column_stack([dw, f(v * w), wf])
    a = np.linalg.lstsq(xv, f(vr), rcond=None)[0]
    b = np.linalg.lstsq(xw, f(wr), rcond=None)[0]
    return a, b


if "--once" in sys.argv:
    a, b = identify()
    print(f"theta (v: θ1 θ3 θ4) {a}, (w: θ2 θ5 θ6) {b}")
    sys.exit(0)

times = []
for _ in range(5):
    t0 = time.perf_counter()
    a, b = identify()
    times.append(time.perf_counter() - t0)
print(f"theta (v: θ1 θ3 θ4) {a}, (w: θ2 θ5 θ6) {b}")
print(f"scipy identify on {len(t)} rows: median {np.median(times):.3f} s, min {min(times):.3f} s")

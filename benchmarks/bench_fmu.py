"""Benchmark: step time of exported FMUs at 1 kHz (median and p99 per step).

Budget (DESIGN §7): FMU step ≤ 100 µs (median). Anchor: the budget itself, and the
in-process simulator's time per sample in the same run.

Each FMU is driven through one medium ramp (23 s, 23 000 steps of 1 ms) twice:

- **C host**: a small C program (compiled here) loads the FMU binary with ``dlopen`` and runs
  the 1 kHz loop — ``fmi2SetReal`` + ``fmi2SetRealInputDerivatives`` + ``fmi2DoStep`` +
  ``fmi2GetReal`` per tick — timing every tick with ``clock_gettime``: what a real-time host
  (HIL, Simulink S-function, Silver) pays per step.
- **Python host**: :class:`clutchlab.physics.fmu.FmuPhysics` (FMPy's FMI 2.0 API via ctypes);
  wall time per step, Python overhead included.

Usage: ``python benchmarks/bench_fmu.py [--model FIT.json] [--runs 3] [--out DIR]``
(without ``--model`` the datasheet parameters are exported; the step cost does not depend
on the values).
"""

from __future__ import annotations

import argparse
import os
import platform
import shutil
import statistics
import subprocess
import tempfile
import time
from pathlib import Path

import fmpy
import numpy as np

from clutchlab.physics import CircuitModel, SimulationSettings, simulate
from clutchlab.physics.fmu import (
    DecisionSpec,
    DidtSpec,
    FmuPhysics,
    GPSpec,
    build_fmu,
    export_physics_fmu,
    inspect_fmu,
    ml_program,
    physics_program,
)
from clutchlab.physics.fmu.build import fmi_headers_dir
from clutchlab.physics.stand import DitherSetting, StandConfig, run_stand

BUDGET_US = 100.0

_HOST = r"""
#include <dlfcn.h>
#include <stdio.h>
#include <stdlib.h>
#include <time.h>
#include "fmi2Functions.h"

static void logger(fmi2ComponentEnvironment e, fmi2String n, fmi2Status s, fmi2String c,
                   fmi2String m, ...) {
    (void)e; (void)n; (void)c;
    fprintf(stderr, "[%d] %s\n", s, m);
}
static double now_ns(void) {
    struct timespec ts; clock_gettime(CLOCK_MONOTONIC, &ts);
    return ts.tv_sec * 1e9 + ts.tv_nsec;
}
#define LOAD(f)                                       \
    f##TYPE* f = (f##TYPE*)dlsym(h, #f);              \
    if (!f) { fprintf(stderr, "no %s\n", #f); return 2; }
/* usage: host LIB GUID DATA NV N OUT RESOURCES VR_OUT VR_IN... ; rows: t, u[NV], du[NV] */
int main(int argc, char** argv) {
    void* h = dlopen(argv[1], RTLD_NOW | RTLD_LOCAL);
    int nv = atoi(argv[4]), n = atoi(argv[5]), k, j, w = 1 + 2 * nv;
    fmi2ValueReference vr_out = (fmi2ValueReference)atoi(argv[8]), vr_in[64];
    fmi2Integer order[64];
    double *d = malloc(sizeof(double) * n * w), *tick = malloc(sizeof(double) * n);
    double *step = malloc(sizeof(double) * n), y = 0, sum = 0;
    fmi2CallbackFunctions cb = {logger, calloc, free, NULL, NULL};
    FILE* f;
    if (!h) { fprintf(stderr, "%s\n", dlerror()); return 2; }
    LOAD(fmi2Instantiate) LOAD(fmi2SetupExperiment) LOAD(fmi2EnterInitializationMode)
    LOAD(fmi2ExitInitializationMode) LOAD(fmi2SetReal) LOAD(fmi2GetReal) LOAD(fmi2DoStep)
    LOAD(fmi2SetRealInputDerivatives) LOAD(fmi2Terminate) LOAD(fmi2FreeInstance)
    for (j = 0; j < nv; j++) { vr_in[j] = (fmi2ValueReference)atoi(argv[9 + j]); order[j] = 1; }
    f = fopen(argv[3], "rb");
    if (!f || fread(d, sizeof(double), (size_t)n * w, f) != (size_t)n * w) return 3;
    fclose(f);
    fmi2Component c = fmi2Instantiate("bench", fmi2CoSimulation, argv[2], argv[7], &cb, 0, 0);
    if (!c) return 4;
    fmi2SetupExperiment(c, 0, 0.0, d[0], 0, 0.0);
    fmi2EnterInitializationMode(c);
    fmi2SetReal(c, vr_in, nv, d + 1);
    fmi2SetRealInputDerivatives(c, vr_in, nv, order, d + 1 + nv);
    if (fmi2ExitInitializationMode(c) > fmi2Warning) return 5;
    for (k = 0; k + 1 < n; k++) {
        const double* r = d + (size_t)k * w;
        double t0 = now_ns(), t1, t2;
        fmi2SetReal(c, vr_in, nv, r + 1);
        fmi2SetRealInputDerivatives(c, vr_in, nv, order, r + 1 + nv);
        t1 = now_ns();
        if (fmi2DoStep(c, r[0], d[(size_t)(k + 1) * w] - r[0], fmi2True) > fmi2Warning) return 6;
        t2 = now_ns();
        fmi2GetReal(c, &vr_out, 1, &y);
        tick[k] = now_ns() - t0;
        step[k] = t2 - t1;
        sum += y;
    }
    fmi2Terminate(c);
    fmi2FreeInstance(c);
    f = fopen(argv[6], "wb");
    fwrite(tick, sizeof(double), n - 1, f);
    fwrite(step, sizeof(double), n - 1, f);
    fclose(f);
    printf("%.17g\n", sum);
    return 0;
}
"""


def _fitted(path: str):
    from clutchlab.physics.fmu import physics_source

    return physics_source(path)


def build_host(folder: Path) -> Path:
    """Compile the C host program."""
    src = folder / "host.c"
    src.write_text(_HOST)
    exe = folder / "host"
    cc = shutil.which(os.environ.get("CC", "gcc")) or "cc"
    cmd = [cc, "-O2", "-I", str(fmi_headers_dir()), "-o", str(exe), str(src), "-ldl"]
    subprocess.run(cmd, check=True)
    return exe


def c_host_times(
    exe: Path, fmu: Path, trace, folder: Path, max_steps: int | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Per-tick and per-doStep times (µs) of the C host on ``trace`` (its first
    ``max_steps`` steps when given)."""
    itf = inspect_fmu(fmu)
    md = itf.model_description
    unzip = Path(fmpy.extract(str(fmu)))
    lib = (
        unzip
        / "binaries"
        / fmpy.platform
        / (md.coSimulation.modelIdentifier + fmpy.sharedLibraryExtension)
    )
    n = len(trace) if max_steps is None else min(len(trace), max_steps + 1)
    u = np.column_stack([trace.get(p.signal)[:n] for p in itf.inputs])
    t = trace.time_s[:n]
    du = np.vstack([np.diff(u, axis=0) / np.diff(t)[:, None], np.zeros((1, u.shape[1]))])
    data = folder / "inputs.bin"
    np.column_stack([t, u, du]).astype("<f8").tofile(data)
    out = folder / "times.bin"
    cmd = [
        str(exe),
        str(lib),
        md.guid,
        str(data),
        str(u.shape[1]),
        str(len(t)),
        str(out),
        (unzip / "resources").as_uri(),
        str(itf.output.value_reference),
        *(str(p.value_reference) for p in itf.inputs),
    ]
    subprocess.run(cmd, check=True, capture_output=True, text=True)
    times = np.fromfile(out, dtype="<f8").reshape(2, -1) * 1e-3
    shutil.rmtree(unzip, ignore_errors=True)
    return times[0], times[1]


def synthetic_gp(n: int, d: int, seed: int, std: bool) -> GPSpec:
    """A GP of ``n`` points in ``d`` features (step cost depends on the sizes only)."""
    rng = np.random.default_rng(seed)
    a = rng.normal(size=(n, n))
    return GPSpec(
        "rq",
        x_mean=np.array([500.0, 100.0, 50.0, 0.0, 8.0][:d]),
        x_scale=np.array([400.0, 60.0, 15.0, 300.0, 6.0][:d]),
        length_scales=np.full(d, 0.5),
        alpha=1.5,
        points=rng.normal(size=(n, d)),
        weights=rng.normal(size=n) * 1e-3,
        y_mean=5.0,
        signal_var=1.0,
        y_scale=3.0,
        k_inv=(a @ a.T / n + np.eye(n)) * 1e-3 if std else None,
    )


def ml_fmus(work: Path, physics_source) -> dict[str, Path]:
    """ML and hybrid FMUs at the sizes of the paper pipeline's defaults (LocalGPRegressor
    max_points 3000, RBF-SVC svc_max_points 4000) and at a typical fitted size (600 bins)."""
    base = ("current_mA", "dither_amp_mA", "dither_freq_Hz")
    didt = (*base, "didt_mA_s")
    rng = np.random.default_rng(0)
    svc = DecisionSpec(
        "rbf",
        mean=np.array([550.0, 110.0, 50.0, 0.0]),
        scale=np.array([300.0, 50.0, 10.0, 100.0]),
        intercept=0.0,
        support=rng.normal(size=(4000, 4)),
        coef=rng.normal(size=4000),
        gamma=1.0,
    )
    physics = physics_program(*physics_source, "command")
    progs = {
        "gp_base, 600 bins, mean+std": ml_program(
            synthetic_gp(600, 3, 1, True), base, name="gp600"
        ),
        "gp_base, 3000 bins, mean only": ml_program(
            synthetic_gp(3000, 3, 2, False), base, with_std=False, name="gp3000"
        ),
        "gp_base, 3000 bins, mean+std": ml_program(
            synthetic_gp(3000, 3, 3, True), base, name="gp3000s"
        ),
        "paper_svc_gp, 4000 SV, 2x3000, mean": ml_program(
            {0: synthetic_gp(3000, 4, 4, False), 1: synthetic_gp(3000, 4, 5, False)},
            didt,
            decision=svc,
            didt=DidtSpec(),
            with_std=False,
            name="svcgp",
        ),
        "hybrid: physics + GP 600, mean+std": ml_program(
            synthetic_gp(600, 4, 6, True),
            (*base, "physics_bar"),
            physics=physics,
            name="hybrid600",
        ),
    }
    return {label: build_fmu(prog, work / f"{prog.name}.fmu") for label, prog in progs.items()}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--model", help="fitted physics model JSON (default: datasheet values)")
    ap.add_argument("--runs", type=int, default=3, help="runs per FMU (median of the medians)")
    ap.add_argument("--out", help="folder for the FMUs (default: a temporary folder)")
    ap.add_argument("--physics-only", action="store_true", help="skip the ML / hybrid FMUs")
    ap.add_argument(
        "--ml-steps", type=int, default=2000, help="steps timed per ML / hybrid FMU (2000)"
    )
    args = ap.parse_args()

    stand = run_stand(StandConfig(settings=(DitherSetting(50.0, "B"),)), progress=False)
    trace = stand.dataset["medium_50Hz_B"]
    base = CircuitModel()
    source = args.model or (base, base.default_params())
    work = Path(args.out or tempfile.mkdtemp(prefix="clutchlab-bench-fmu-"))
    work.mkdir(parents=True, exist_ok=True)
    print(
        f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
        f"Python {platform.python_version()}, load average {os.getloadavg()[0]:.1f}"
    )
    print(
        f"trace: {trace.name}, {trace.duration_s:.1f} s at {trace.sample_rate_Hz:.0f} Hz "
        f"({len(trace) - 1} steps of 1 ms); model: {args.model or 'datasheet parameters'}"
    )
    fmus = {
        "physics, command drive": export_physics_fmu(source, work / "physics_command.fmu"),
        "physics, measured drive": export_physics_fmu(
            source, work / "physics_measured.fmu", drive="measured"
        ),
        "stand model (3 effects), command": export_physics_fmu(
            (stand.model, stand.model.default_params()),
            work / "stand_command.fmu",
            name="stand_circuit_command",
        ),
    }
    if not args.physics_only:
        model, params = (base, base.default_params()) if not args.model else _fitted(args.model)
        fmus |= ml_fmus(work, (model, params))
    exe = build_host(work)
    rows = []
    physics_labels = list(fmus)[:3]
    for label, fmu in fmus.items():
        steps = None if label in physics_labels else args.ml_steps
        med_tick, p99_tick, med_step, p99_step, worst, py = [], [], [], [], [], []
        for _ in range(args.runs):
            tick, step = c_host_times(exe, fmu, trace, work, steps)
            med_tick.append(np.median(tick))
            p99_tick.append(np.percentile(tick, 99))
            med_step.append(np.median(step))
            p99_step.append(np.percentile(step, 99))
            worst.append(tick.max())
            if steps is None:  # the import path (FmuPhysics) matters for physics FMUs
                t0 = time.perf_counter()
                FmuPhysics(fmu).simulate(trace)
                py.append((time.perf_counter() - t0) / (len(trace) - 1) * 1e6)
        rows.append(
            (
                label,
                statistics.median(med_tick),
                statistics.median(p99_tick),
                statistics.median(med_step),
                statistics.median(p99_step),
                statistics.median(worst),
                statistics.median(py) if py else float("nan"),
            )
        )
    drive_ref = {}
    for drive in ("command", "measured"):
        settings = SimulationSettings(drive=drive)
        simulate(base, None, trace, settings)
        t0 = time.perf_counter()
        simulate(base, None, trace, settings)
        drive_ref[drive] = (time.perf_counter() - t0) / (len(trace) - 1) * 1e6
    print(
        f"\n{'FMU':38s} {'tick med':>9s} {'tick p99':>9s} {'doStep med':>11s} "
        f"{'doStep p99':>11s} {'tick max':>9s} {'Python/step':>12s} {'med/budget':>11s}"
    )
    for label, mt, pt, ms, ps, mx, py in rows:
        print(
            f"{label:38s} {mt:9.2f} {pt:9.2f} {ms:11.2f} {ps:11.2f} {mx:9.1f} {py:12.2f} "
            f"{mt / BUDGET_US:11.3f}"
        )
    print(
        "(µs; tick = set inputs + derivatives + doStep + get output, as a C host runs it; "
        f"ML / hybrid rows: first {args.ml_steps} steps of the ramp)"
    )
    print(
        "in-process simulator per sample (compiled chunk, same model): "
        + ", ".join(f"{d} {v:.2f} µs" for d, v in drive_ref.items())
    )
    worst_med = max(r[1] for r in rows)
    print(
        f"\nworst median tick {worst_med:.2f} µs (budget ≤ {BUDGET_US:g} µs): "
        f"{'PASS' if worst_med <= BUDGET_US else 'FAIL'}"
    )


if __name__ == "__main__":
    main()

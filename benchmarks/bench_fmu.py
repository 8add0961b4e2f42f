"""Benchmark: step time of exported FMUs at 1 kHz (median and p99 per step).

Budget (DESIGN §7): FMU step ≤ 100 µs (median). Anchor: the budget itself, and the
in-process simulator's time per sample in the same run.

FMUs: the physics model (both drives, and the stand's model with its effects), and the four
ML variants trained here on the training ramps (fast + slow) at their default sizes, as
``clutchlab train`` trains them — ``gp_base``, and ``gp_didt``, ``paper_svc_gp`` and
``hybrid`` with ``--causal`` so that they export exactly — each without and with the
predictive-std output (the GP's std given its coarse std bins, ``max_std_points``). Each FMU
is driven through one medium ramp (23 s, 23 000 steps of 1 ms; with ``--std-steps N`` the
rows with the std output run its first N steps once):

- **C host**: a small C program (compiled here) loads the FMU binary with ``dlopen`` and runs
  the 1 kHz loop — ``fmi2SetReal`` + ``fmi2SetRealInputDerivatives`` + ``fmi2DoStep`` +
  ``fmi2GetReal`` per tick — timing every tick with ``clock_gettime``: what a real-time host
  (HIL, Simulink S-function, Silver) pays per step.
- **Python host** (physics rows): :class:`clutchlab.physics.fmu.FmuPhysics` (FMPy's FMI 2.0
  API via ctypes); wall time per step, Python overhead included.

It also prints, per ML FMU, the largest difference from the in-process model (evaluated at
every sample) on the medium-ramp experiments (must-show 1: ≤ 0.01 bar).

Usage: ``python benchmarks/bench_fmu.py [--model FIT.json] [--data DATASET] [--runs 3]
[--out DIR]`` (without ``--model`` the datasheet parameters are the physics; without
``--data`` the default stand is generated).
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
    FmuPhysics,
    build_fmu,
    export_physics_fmu,
    inspect_fmu,
)
from clutchlab.physics.fmu.adapters import ml_program_from
from clutchlab.physics.fmu.build import fmi_headers_dir
from clutchlab.physics.stand import StandConfig, run_stand

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


def trained_models(data, physics) -> dict:
    """The four ML variants trained on the training ramps of ``data`` (fast + slow) as
    ``clutchlab train`` does: ``gp_base`` as is (its features are FMU inputs), ``gp_didt``,
    ``paper_svc_gp`` and ``hybrid`` with ``--causal`` (exact export).

    Each with its std options at the GP's own std (``mean_only``: no latch-timing
    mixture, rate bridge, residual-variance or per-frequency noise floor), which is the
    std the FMU outputs, so that ``max|dstd|`` compares like with like; the mean, the
    FMU and its step time do not depend on them."""
    from clutchlab.residual_ml import PhysicsPredictor, SVCPartitionedGP, make_variant, mean_only
    from clutchlab.residual_ml.features import PHYSICS_FEATURES, causal_features
    from clutchlab.residual_ml.hybrid import HYBRID_FEATURES

    train = data.select(ramps=["fast", "slow"])
    models = {}
    for variant in ("gp_base", "gp_didt", "paper_svc_gp"):
        names = make_variant(variant)._builder().names
        models[variant] = mean_only(make_variant(variant, features=causal_features(names)))
    own = causal_features(tuple(f for f in HYBRID_FEATURES if f not in PHYSICS_FEATURES))
    model, params = physics
    models["hybrid"] = make_variant(
        "hybrid",
        physics=PhysicsPredictor(tuple(model.effect_names), params.changed()),
        residual=mean_only(SVCPartitionedGP(features=own)),
    )
    for variant, est in models.items():
        t0 = time.perf_counter()
        est.fit(train)
        print(f"trained {variant} in {time.perf_counter() - t0:.1f} s", flush=True)
    return models


def ml_fmus(work: Path, models: dict) -> dict[str, tuple[Path, object, bool]]:
    """FMU per trained model, without and with the predictive-std output."""
    out = {}
    for variant, est in models.items():
        if getattr(est, "form_", None) == "physics":
            # leave-one-experiment-out chose the physics alone: its FMU is the physics one
            print(
                f"{variant}: chose its physics form (leave-one-experiment-out RMSE "
                f"{getattr(est, 'form_scores_', {})}); its FMU is the physics FMU above",
                flush=True,
            )
            continue
        for with_std in (False, True):
            label = f"{variant}{', mean+std' if with_std else ''}"
            prog = ml_program_from(est, with_std=with_std, name=variant)
            path = work / f"{variant}{'_std' if with_std else ''}.fmu"
            out[label] = (build_fmu(prog, path), est, with_std)
    return out


def _command_only(trace):
    signals = {k: v for k, v in trace.signals.items() if k != "current_mA"}
    return type(trace)(trace.name, signals, trace.meta)


def fmu_vs_in_process(fmu: Path, est, with_std: bool, traces) -> tuple[float, float]:
    """Max |FMU − in-process| (bar) of the pressure and of the std on ``traces``; the
    in-process model evaluated at every sample (``knot_tol=0``)."""
    own = est.residual_ if hasattr(est, "residual_") else est
    knot_tol = own.knot_tol
    own.set_params(knot_tol=0.0)
    worst, worst_std = 0.0, float("nan")
    try:
        for tr in traces:
            tr = _command_only(tr) if hasattr(est, "residual_") else tr
            sim = FmuPhysics(fmu).simulate(tr)
            if with_std:
                mean, std = est.predict(tr, return_std=True)
                err = np.abs(sim.outputs["clutch_pressure_std_bar"] - std).max()
                worst_std = err if np.isnan(worst_std) else max(worst_std, err)
            else:
                mean = est.predict(tr)
            worst = max(worst, float(np.abs(sim.pressure_bar - mean).max()))
    finally:
        own.set_params(knot_tol=knot_tol)
    return worst, worst_std


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--model", help="fitted physics model JSON (default: datasheet values)")
    ap.add_argument("--data", help="dataset folder (default: the default stand, generated)")
    ap.add_argument("--runs", type=int, default=3, help="runs per FMU (median of the medians)")
    ap.add_argument("--out", help="folder for the FMUs (default: a temporary folder)")
    ap.add_argument("--physics-only", action="store_true", help="skip the ML / hybrid FMUs")
    ap.add_argument(
        "--std-steps",
        type=int,
        default=None,
        help="steps timed (once) and compared per FMU with the std output (default: the "
        "whole ramp, --runs runs, all medium ramps compared, as the rows without std)",
    )
    args = ap.parse_args()

    if args.data:
        from clutchlab.data import load_dataset

        data = load_dataset(args.data)
    else:
        data = run_stand(StandConfig(), progress=False).dataset
    trace = data["medium_50Hz_B"]
    medium = list(data.select(ramps=["medium"]))
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
        f"({len(trace) - 1} steps of 1 ms); physics: {args.model or 'datasheet parameters'}"
    )
    stand_model = StandConfig().model()
    fmus: dict[str, tuple[Path, object, bool]] = {
        "physics, command drive": (
            export_physics_fmu(source, work / "physics_command.fmu"),
            None,
            False,
        ),
        "physics, measured drive": (
            export_physics_fmu(source, work / "physics_measured.fmu", drive="measured"),
            None,
            False,
        ),
        "stand model (its effects), command": (
            export_physics_fmu(
                (stand_model, stand_model.default_params()),
                work / "stand_command.fmu",
                name="stand_circuit_command",
            ),
            None,
            False,
        ),
    }
    if not args.physics_only:
        physics = (base, base.default_params()) if not args.model else _fitted(args.model)
        models = trained_models(data, physics)
        fmus |= ml_fmus(work, models)
    exe = build_host(work)
    rows = []
    for label, (fmu, est, with_std) in fmus.items():
        steps = args.std_steps if with_std else None
        runs = 1 if steps else args.runs
        med_tick, p99_tick, med_step, p99_step, worst, py = [], [], [], [], [], []
        for _ in range(runs):
            tick, step = c_host_times(exe, fmu, trace, work, steps)
            med_tick.append(np.median(tick))
            p99_tick.append(np.percentile(tick, 99))
            med_step.append(np.median(step))
            p99_step.append(np.percentile(step, 99))
            worst.append(tick.max())
            if est is None:  # the import path (FmuPhysics) matters for physics FMUs
                t0 = time.perf_counter()
                FmuPhysics(fmu).simulate(trace)
                py.append((time.perf_counter() - t0) / (len(trace) - 1) * 1e6)
        err = (float("nan"), float("nan"))
        if est is not None:
            n = (steps or len(trace)) + 1
            traces = [trace.slice_time(None, trace.time_s[n - 1])] if steps else medium
            err = fmu_vs_in_process(fmu, est, with_std, traces)
        rows.append(
            (
                label,
                statistics.median(med_tick),
                statistics.median(p99_tick),
                statistics.median(med_step),
                statistics.median(p99_step),
                statistics.median(worst),
                statistics.median(py) if py else float("nan"),
                *err,
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
        f"\n{'FMU':36s} {'tick med':>9s} {'tick p99':>9s} {'doStep med':>11s} "
        f"{'doStep p99':>11s} {'tick max':>9s} {'Python/step':>12s} {'med/budget':>11s} "
        f"{'max|dp| bar':>12s} {'max|dstd| bar':>14s}"
    )
    for label, mt, pt, ms, ps, mx, py, ep, es in rows:
        print(
            f"{label:36s} {mt:9.2f} {pt:9.2f} {ms:11.2f} {ps:11.2f} {mx:9.1f} {py:12.2f} "
            f"{mt / BUDGET_US:11.3f} {ep:12.2e} {es:14.2e}"
        )
    print(
        "(µs; tick = set inputs + derivatives + doStep + get output, as a C host runs it; "
        + (
            f"rows with the std output: first {args.std_steps} steps of the ramp, one run; "
            if args.std_steps
            else ""
        )
        + "max|dp|, max|dstd|: FMU against the in-process model at every sample on the medium "
        "ramp experiments, pressure and predictive std)"
    )
    print(
        "in-process simulator per sample (compiled chunk, same model): "
        + ", ".join(f"{d} {v:.2f} µs" for d, v in drive_ref.items())
    )
    for name, subset in (("without std", [r for r in rows if "std" not in r[0]]), ("all", rows)):
        worst_med = max(r[1] for r in subset)
        print(
            f"worst median tick, {name}: {worst_med:.2f} µs (budget ≤ {BUDGET_US:g} µs): "
            f"{'PASS' if worst_med <= BUDGET_US else 'FAIL'}"
        )
    print(f"load average at the end: {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()

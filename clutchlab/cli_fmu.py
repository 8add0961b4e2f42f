"""``clutchlab export-fmu``: a fitted model (or a design) as an FMI 2.0 co-simulation FMU."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

__all__ = ["register"]


def _is_ml_model(path: str) -> bool:
    """Whether ``path`` claims to be a model saved by ``clutchlab.residual_ml.save_model``;
    the loader then checks it."""
    from .data import model_file_kind

    return model_file_kind(path) == "ml"


def _export(args: argparse.Namespace) -> Path:
    from .physics.fmu import FmuError, build_fmu, export_physics_fmu
    from .physics.fmu.physics import check_export_options

    check_export_options(args.substeps, args.step, args.stop_time)  # before any work
    if _is_ml_model(args.model):
        from .physics.fmu.adapters import ml_program_from, std_terms_not_exported
        from .residual_ml import check_model, load_model, no_substeps_message

        if args.substeps is not None:
            raise FmuError(no_substeps_message(args.model))

        model = load_model(args.model)  # checked as it is read
        check_model(model, args.model)  # the in-memory model the FMU is built from
        if not args.no_std and (omitted := std_terms_not_exported(model)):
            print(
                "note: the FMU's std output is the GP's own (its std and observation noise); "
                "the model's predict(return_std=True) also has: " + "; ".join(omitted)
            )
        program = ml_program_from(
            model,
            with_std=not args.no_std,
            approximate_didt=args.approximate_didt,
            name=args.name,
            step_s=args.step,
            stop_time_s=args.stop_time,
        )
        return build_fmu(program, args.out)
    return export_physics_fmu(
        args.model,
        args.out,
        drive=args.drive,
        substeps=args.substeps,
        name=args.name,
        step_s=args.step,
        stop_time_s=args.stop_time,
    )


def _cmd_export_fmu(args: argparse.Namespace) -> int:
    import fmpy
    from fmpy.validation import validate_fmu

    out = _export(args)
    md = fmpy.read_model_description(str(out))
    problems = validate_fmu(str(out))
    inputs = [v for v in md.modelVariables if v.causality == "input"]
    outputs = [v for v in md.modelVariables if v.causality == "output"]
    n_par = sum(v.causality == "parameter" for v in md.modelVariables)
    print(f"wrote {out} (FMI {md.fmiVersion} co-simulation, {md.coSimulation.modelIdentifier})")
    print("  inputs:  " + ", ".join(f"{v.name} [{v.unit or '-'}]" for v in inputs))
    print("  outputs: " + ", ".join(f"{v.name} [{v.unit or '-'}]" for v in outputs))
    print(f"  {n_par} parameters; default experiment step {md.defaultExperiment.stepSize} s")
    print("  fmpy.validation: " + ("no problems" if not problems else "; ".join(problems)))
    if args.json:
        doc = {
            "fmu": str(out),
            "model_identifier": md.coSimulation.modelIdentifier,
            "guid": md.guid,
            "drive": None if _is_ml_model(args.model) else args.drive,
            "inputs": [v.name for v in inputs],
            "outputs": [v.name for v in outputs],
            "parameters": n_par,
            "validation_problems": problems,
        }
        from .cli import write_json_output

        write_json_output(args.json, json.dumps(doc, indent=2))
    return 0 if not problems else 1


def register(sub) -> None:
    """Add the ``export-fmu`` subcommand to the ``clutchlab`` parser."""
    p = sub.add_parser(
        "export-fmu", help="export a fitted model (or a design) as an FMI 2.0 co-simulation FMU"
    )
    p.add_argument(
        "model",
        help="fitted physics model JSON (clutchlab fit-physics --out), a parameter file of a "
        "design before any fit (clutchlab params --out; its effects are those its parameters "
        "belong to) or a residual_ml model JSON (clutchlab train --out; gp_didt, "
        "paper_svc_gp and hybrid trained with --causal export exactly)",
    )
    p.add_argument("--out", required=True, help="FMU file to write (.fmu)")
    p.add_argument(
        "--drive",
        default="command",
        choices=["command", "measured"],
        help="inputs: nominal current + dither (command, default) or measured current",
    )
    p.add_argument(
        "--substeps",
        type=int,
        default=None,
        help="physics models: ROS2 steps per internal step of at most 1 ms, 1..16 (default 4)",
    )
    p.add_argument("--name", default=None, help="model identifier (default clutch_circuit_DRIVE)")
    p.add_argument(
        "--step",
        type=float,
        default=1e-3,
        help="communication step of the FMU's default experiment, s (1e-3); the FMU "
        "integrates in internal steps of at most 1 ms at any communication step",
    )
    p.add_argument("--stop-time", type=float, default=23.0, help="default experiment stop, s")
    p.add_argument(
        "--no-std", action="store_true", help="ML models: no predictive-std output (faster)"
    )
    p.add_argument(
        "--approximate-didt",
        action="store_true",
        help="ML models trained on the centred dI/dt / direction (without `train --causal`): "
        "export anyway with causal stand-ins; APPROXIMATE, the output moves at ramp "
        "reversals (retrain with --causal for an exact FMU)",
    )
    p.add_argument("--json", help="write a summary as JSON here")
    p.set_defaults(func=_cmd_export_fmu, file_out="fmu")

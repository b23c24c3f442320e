"""Hand-off files a robot stack reads directly: ``calibration.yaml`` and a URDF joint snippet.

"The" calibration is the first converged solver in the scenario's solver order; every solver's
estimate is kept under ``solvers:`` as well. Numbers are taken from the same document as
``result.json`` and written with full (repr) precision, so both files hold identical floats.
Nothing time-dependent is written: the same run gives the same bytes.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any
from xml.etree import ElementTree as ET

import numpy as np
import yaml

from nlp_calib.core.errors import UsageError
from nlp_calib.core.files import atomic_write_bytes, atomic_write_text
from nlp_calib.core.text import escaped, unprintable
from nlp_calib.core.version import __version__
from nlp_calib.outputs import urdf
from nlp_calib.outputs.results import result_document, sigmas
from nlp_calib.results import CalibrationRun, Encoder, codec
from nlp_calib.results.layout import LAYOUT_VERSION
from nlp_calib.results.mount import LogMount, SensorMount

CALIBRATION_FILE = "calibration.yaml"
URDF_FILE = "sensor_mount.urdf.xml"
ROBOT_URDF_FILE = "robot.urdf"
PARENT_FRAME = "base_link"


def _solver_entry(res: Mapping[str, Any]) -> dict[str, Any]:
    keys = ("converged", "reason", "cost", "chi2", "inliers", "residuals", "iterations")
    return {
        **{k: res[k] for k in keys},
        "parameters": res["params"],
        # result.json's σ: null for what the fit held rather than estimated.
        "std": res["std"],
        "std_white_noise": res["std_white_noise"],
        "correlation": res["correlation"],
    }


def calibration_dict(run: CalibrationRun) -> dict[str, Any] | None:
    """The ``calibration.yaml`` document, or None when no estimate is handed off."""
    found = handoff_mount(run)
    if found is None:
        return None
    solver, mount = found
    doc = result_document(run)
    best = doc["solvers"][solver]
    sc = run.scenario
    ds = doc["dataset"]
    return {
        "tool": {"name": "nlp_calib", "version": __version__},
        # Every parameter below in its block (model, mount, clock), with its log, unit, status,
        # range and needed precision: what `nlp-calib check` reads the file by.
        "layout": {"version": LAYOUT_VERSION, **codec.to_data(run.stated_layout())},
        "scenario": {"name": sc.name, "path": sc.path},
        "model": doc["model"],
        "dataset": {
            "path": ds["path"],
            "records": ds["records"],
            "used": ds["used"],
            "fit": ds["fit"],
            "tracker_lag_s": doc["alignment"]["tracker_lag_s"],
        },
        # A joint fit: every log it was fitted to (the block above describes the first).
        **({"datasets": list(sc.datasets)} if sc.datasets else {}),
        "solver": solver,
        "solver_choice": "first converged solver in the order " + ", ".join(run.solver_order()),
        "frames": {"parent": PARENT_FRAME, "sensor": mount.child},
        "sensor": _sensor_entry(run),
        "mount": _mount_entry(mount),
        # A mount per log: each log's own, one URDF joint each (the block above is the first's).
        **_per_log_mounts(run, solver),
        # A sensor fitted beside the reference (a gyro's IMU): its own URDF joint.
        **_beside_mount(run, solver),
        "parameters": best["params"],
        # What the fit held rather than estimated (a value given, not calibrated: no σ, std null).
        **_held_entry(run, solver),
        # What it estimated but did not determine well enough to use, with why: not calibrated.
        **({"not_determined": run.doubts(solver)} if run.doubts(solver) else {}),
        **_sigma_entries(run, solver, doc),
        # The formulation fitted: what `nlp-calib check` needs to judge this calibration on a new log.
        "objective": {"residual": doc["residual"], "robust": doc["robust"]},
        "correlation": best["correlation"],
        "units": dict(sc.units),
        # The units "per t_max ticks" and "per tick" refer to these encoders' ranges; a wheel's
        # counts per turn (for its radius) only where the user gave them.
        "encoders": [_encoder(e) for e in run.log.encoders],
        # The odometry's noise as a filter's process noise takes it (ros2_control.yaml's diagonals
        # are the same noise at one distance and one interval).
        **_noise_entry(run, solver),
        "verdict": {"level": run.verdict.level, "reasons": list(run.verdict.reasons)},
        "solvers": {name: _solver_entry(res) for name, res in doc["solvers"].items()},
    }


def _sigma_entries(run: CalibrationRun, solver: str, doc: Mapping[str, Any]) -> dict[str, Any]:
    """The σ to believe of ``solver``'s estimate and what `nlp-calib check` weighs it by."""
    best = doc["solvers"][solver]
    return {
        "std": best["std"],
        "std_white_noise": best["std_white_noise"],
        # Errors of each window's own average over a log as white noise does (the drift check).
        **({"std_residuals": best["std_residuals"]} if best.get("std_residuals") else {}),
        # Blocks of the drive that disagree beyond their σ: a spread that averages over a log too.
        **({"std_block_scatter": best["std_block_scatter"]} if best.get("std_block_scatter") else {}),
        "std_blocks": sigmas(run, solver, (doc["crossvalidation"] or {}).get("std_blocks")),
        # What the slip check's lines leave open of a slip the model lacks, in 'std' already.
        **_shift_entry(run, solver, "std_slip", run.checks.slip),
        # What the held values' plausible errors move each estimate by, in 'std' already.
        **_shift_entry(run, solver, "std_held", run.checks.held),
        # ... and the values held (a check's refit that holds others does not share that part).
        **({"held_values": run.checks.held_values()} if run.checks.held_values() else {}),
        # The jackknife σ's folds: its degrees of freedom + 1.
        "std_blocks_folds": len(run.checks.crossval.converged) if run.checks.crossval is not None else 0,
    }


def _sensor_entry(run: CalibrationRun) -> dict[str, Any]:
    """Which sensor the calibration holds the mount of (its mount as a URDF joint: ``mount``)."""
    info = run.scenario.sensor
    return {
        "kind": info.kind,
        "group": info.group,
        "scale": info.scale,
        "params": list(info.params),
        "convention": info.convention,
        "held": {n: run.initial.get(n, 0.0) for n in info.held},
    }


def _noise_entry(run: CalibrationRun, solver: str) -> dict[str, Any]:
    """``odometry_noise:``: the odometry's variance per metre driven and per radian turned (along,
    across, heading), each input's noise per interval, and the share of the drift segments' errors
    within 2σ; none: no entry."""
    controller = run.reports[solver].controller
    noise = controller.noise if controller is not None else None
    rates = noise.rates if noise is not None else None
    if noise is None or rates is None:
        return {}
    axes = ("along", "across", "heading")
    return {
        "odometry_noise": {
            "variance_per_metre": dict(zip(axes, rates.per_metre)),
            "variance_per_radian": dict(zip(axes, rates.per_radian)),
            "units": {"along": "m²", "across": "m²", "heading": "rad²"},
            "inputs_per_interval": dict(noise.input_noise),
            # None: no drift segment to judge it by.
            "segments_within_2sigma": rates.coverage,
            "segments": rates.segments,
            # A base that pivots: the heading's variance per radian turned on the spot, in place
            # of variance_per_radian's there (a skid-steer's wheels scrub on a pivot, not on an arc).
            **(
                {"heading_variance_per_radian_on_the_spot": rates.on_spot}
                if rates.on_spot is not None
                else {}
            ),
            # The pivots the ground slipped on, left out of the rates: the heading's variance they
            # add per radian turned on the spot, for a filter that knows when the robot pivots.
            **(
                {
                    "slipped_pivots": {
                        "heading_variance_per_radian": rates.slip_per_radian,
                        "pivots": rates.slipped,
                    }
                }
                if rates.slipped
                else {}
            ),
        }
    }


def _held_entry(run: CalibrationRun, solver: str) -> dict[str, Any]:
    """``held:``: each parameter the fit held (given under ``known:``, held under ``fixed:``, or
    held at its guess because the drive cannot determine it, or a time offset the run holds with
    no σ), with why; none: no entry."""
    held = run.held_in(solver)
    return {"held": dict(held)} if held else {}


def _per_log_mounts(run: CalibrationRun, solver: str) -> dict[str, Any]:
    every = run.reports[solver].mounts
    return {"mounts": [{"log": m.log, **_mount_entry(m.mount)} for m in every]} if every else {}


def _beside_mount(run: CalibrationRun, solver: str) -> dict[str, Any]:
    beside = run.reports[solver].beside
    return {"beside": _mount_entry(beside)} if beside is not None else {}


def _encoder(e: Encoder) -> dict[str, Any]:
    entry: dict[str, Any] = {"name": e.name, "kind": e.kind, "unit": e.unit, "range": e.range}
    if e.per_turn is not None:
        entry["counts_per_turn"] = e.per_turn
    return entry


def _mount_entry(mount: SensorMount) -> dict[str, Any]:
    """The mount as the URDF files state it: the joint, its origin, the pose in base_link with each
    calibrated component's 1σ, and where every other component comes from."""
    return {
        "joint": mount.joint,
        "parent": mount.parent,
        "child": mount.child,
        "xyz": list(mount.xyz),
        "rpy": list(mount.rpy),
        "pose_in_base_link": dict(mount.pose),
        "std": {c: mount.std[c] for c in mount.calibrated},
        "calibrated": list(mount.calibrated),
        "nominal": dict(mount.nominal),
        # Estimated, not determined well enough to use: no URDF file is written with them.
        **({"undetermined": dict(mount.undetermined)} if mount.undetermined else {}),
    }


# libyaml's emitter where PyYAML has it (4x faster; the same text but for characters beyond
# U+FFFF, which it writes escaped: the same value read back).
_SAFE_DUMPER: type[yaml.SafeDumper] = getattr(yaml, "CSafeDumper", yaml.SafeDumper)


class _Dumper(_SAFE_DUMPER):  # type: ignore[valid-type,misc]
    """Block mappings, but flow-style lists of scalars (matrix rows, record ranges)."""

    def ignore_aliases(self, data: Any) -> bool:
        return True  # repeated blocks are written out in full: no &anchors for readers to resolve


def _represent_list(dumper: yaml.SafeDumper, data: list[Any]) -> yaml.Node:
    flow = all(not isinstance(v, (list, dict)) for v in data)
    return dumper.represent_sequence("tag:yaml.org,2002:seq", data, flow_style=flow)


_Dumper.add_representer(list, _represent_list)


def _represent_str(dumper: yaml.SafeDumper, data: str) -> yaml.Node:
    # A line break YAML knows and PyYAML writes raw (U+0085), a control: double-quoted, escaped.
    style = '"' if unprintable(data) is not None else None
    return dumper.represent_scalar("tag:yaml.org,2002:str", data, style=style)


_Dumper.add_representer(str, _represent_str)


def _shift_entry(
    run: CalibrationRun, solver: str, key: str, std: Callable[[tuple[str, ...]], np.ndarray]
) -> dict[str, Any]:
    """``key``: each parameter's σ of a shift the whole drive shares (``std``: the slip's, the held
    values'; null: none), where a check measured it."""
    names = run.reports[solver].uncertainty.names
    found = {n: float(v) if math.isfinite(v) else None for n, v in zip(names, std(names))}
    if all(v is None for v in found.values()):
        return {}
    return {key: sigmas(run, solver, found)}


def _shift_words(doc: Mapping[str, Any]) -> str:
    """The header's end: the shifts 'std' adds in quadrature, where it does."""
    said = {
        "std_slip": "'std_slip' (a slip of the tyres the drive's speeds leave open)",
        "std_held": "'std_held' (what the held values' plausible errors move)",
    }
    added = [words for key, words in said.items() if key in doc]
    return f",\n# with {' and '.join(added)} added in quadrature.\n" if added else ".\n"


def calibration_yaml(doc: Mapping[str, Any]) -> str:
    """YAML text of a calibration document (a comment header, then the document)."""
    head = (
        f"# Wheeled-robot calibration by nlp_calib {doc['tool']['version']}, scenario "
        f"{escaped(doc['scenario']['name'])}.\n"
        f"# 'parameters' are {doc['solver']}'s estimate ({doc['solver_choice']}); 'std' is the 1 sigma to\n"
        "# believe: the larger of 'std_white_noise' (white tracker and encoder noise only: a floor) and\n"
        "# 'std_blocks' (the spread of fits each without one block of the drive: every error that varies)"
        + (_shift_words(doc))
        + f"# {_mount_words(doc)}: pose of the '{escaped(doc['frames']['sensor'])}' frame in "
        f"'{escaped(doc['frames']['parent'])}'.\n"
    )
    body = yaml.dump(
        dict(doc), Dumper=_Dumper, sort_keys=False, default_flow_style=False, allow_unicode=True, width=1000
    )
    return head + body


def _mount_words(doc: Mapping[str, Any]) -> str:
    """The mount's parameters as the header comment names them (with what the sensor says of them)."""
    sensor = doc["sensor"]
    words = ", ".join(sensor["params"])
    return f"{words} ({sensor['convention']})" if sensor.get("convention") else words


def _comment_text(text: str) -> str:
    # '--' may not appear inside an XML comment, nor '-' at its end; a control character nowhere.
    text = escaped(text)
    while "--" in text:
        text = text.replace("--", "- -")
    return text + " " if text.endswith("-") else text


def _joint(mount: SensorMount) -> ET.Element:
    joint = ET.Element("joint", {"name": mount.joint, "type": "fixed"})
    ET.SubElement(joint, "parent", {"link": mount.parent})
    ET.SubElement(joint, "child", {"link": mount.child})
    ET.SubElement(joint, "origin", urdf.origin_text(mount))
    return joint


def _xml(element: ET.Element, comment: str) -> str:
    ET.indent(element, space="  ")
    body = ET.tostring(element, encoding="unicode")
    return f'<?xml version="1.0"?>\n<!--{_comment_text(comment)}-->\n{body}\n'


def _mount_of(run: CalibrationRun, solver: str) -> SensorMount:
    mount = run.reports[solver].mount
    if mount is None:
        raise UsageError(f"the result of {run.scenario.name} holds no mount for {solver}; run it again")
    return mount


def handoff_mount(run: CalibrationRun) -> tuple[str, SensorMount] | None:
    """The handed-off solver and its estimate's mount (None: nothing is handed off)."""
    solver = run.handoff_solver()
    mount = run.reports[solver].mount if solver is not None else None
    return None if solver is None or mount is None else (solver, mount)


def urdf_mount(run: CalibrationRun) -> tuple[str, SensorMount] | None:
    """:func:`handoff_mount` when a URDF can state it: None also when a component of the mount
    (any log's) is not determined well enough to use. A robot loads every number of a joint, and
    a URDF cannot comment one out: the file is left out, ``calibration.yaml`` says why."""
    found = handoff_mount(run)
    if found is None:
        return None
    report = run.reports[found[0]]
    every = [found[1], *(m.mount for m in report.mounts), *([report.beside] if report.beside else [])]
    return None if any(m.undetermined for m in every) else found


def urdf_joint(
    run: CalibrationRun, solver: str, mount: SensorMount | None = None, users: bool = False
) -> str:
    """A URDF ``<joint>`` placing the sensor's link with ``solver``'s estimate (``mount``: its
    report's unless given): on ``base_link``, or (``users``: ``--urdf``) the user's own joint of
    that link, to paste over the one there."""
    every = run.reports[solver].mounts
    if every and not users:
        return _log_joints(run, solver, every)
    mount = mount or _mount_of(run, solver)
    beside = run.reports[solver].beside
    if beside is not None and not users:
        return _beside_joints(run, solver, mount, beside)
    where = (
        f"It is your joint '{mount.joint}' re-posed, as in robot.urdf: replace yours with it."
        if users
        else f"Paste this joint into the robot's <robot> description; the link '{mount.child}' must be "
        "declared there."
    )
    comment = (
        f" Sensor mounting pose calibrated by nlp_calib {__version__}: scenario {run.scenario.name}, "
        f"solver {solver}. {mount.words().capitalize()}. {where} "
    )
    return _xml(_joint(mount), comment)


def _log_joints(run: CalibrationRun, solver: str, every: Sequence[LogMount]) -> str:
    """One joint per log's own mount (a fit with a mount per log), each log's sensor its own link."""
    robot = ET.Element("robot", {"name": run.scenario.name})
    for m in every:
        robot.append(_joint(m.mount))
    links = ", ".join(f"'{m.mount.child}'" for m in every)
    comment = (
        f" Sensor mounting poses calibrated by nlp_calib {__version__}: scenario {run.scenario.name}, "
        f"solver {solver}, one per log ({', '.join(m.log for m in every)}). "
        f"{every[0].mount.words().capitalize()}. Paste these joints into the robot's <robot> "
        f"description; the links {links} must be declared there. "
    )
    return _xml(robot, comment)


def _beside_joints(run: CalibrationRun, solver: str, mount: SensorMount, beside: SensorMount) -> str:
    """The reference's joint and the joint of the sensor fitted beside it (a gyro's IMU)."""
    robot = ET.Element("robot", {"name": run.scenario.name})
    robot.append(_joint(mount))
    robot.append(_joint(beside))
    comment = (
        f" Sensor mounting poses calibrated by nlp_calib {__version__}: scenario {run.scenario.name}, "
        f"solver {solver}, one joint per sensor. '{mount.child}': {mount.words()}. '{beside.child}': "
        f"{beside.words()}. Paste these joints into the robot's <robot> description; the links "
        f"'{mount.child}' and '{beside.child}' must be declared there. "
    )
    return _xml(robot, comment)


def urdf_robot(run: CalibrationRun, solver: str, mount: SensorMount | None = None) -> str:
    """A complete URDF: a ``<robot>`` with ``base_link``, the sensor's link and the calibrated joint
    (every log's own, with a mount per log)."""
    mount = mount or _mount_of(run, solver)
    mounts = [m.mount for m in run.reports[solver].mounts] or [mount]
    beside = run.reports[solver].beside
    mounts += [beside] if beside is not None else []
    robot = ET.Element("robot", {"name": run.scenario.name})
    ET.SubElement(robot, "link", {"name": mount.parent})
    for m in mounts:
        ET.SubElement(robot, "link", {"name": m.child})
    for m in mounts:
        robot.append(_joint(m))
    # What each joint's numbers are (calibrated, given, not known, not determined well enough),
    # as URDF_FILE says it: a value given or not determined is never passed off as calibrated.
    said = (
        f"{mount.words().capitalize()}."
        if len(mounts) == 1
        else " ".join(f"'{m.child}': {m.words()}." for m in mounts)
    )
    comment = (
        f" The sensor mount calibrated by nlp_calib {__version__}: scenario {run.scenario.name}, "
        f"solver {solver}. {said} A complete robot description (base and sensor links, the fixed "
        f"joint) that URDF tools load as it is; {URDF_FILE} holds the joint alone for pasting. "
    )
    return _xml(robot, comment)


def _none(path: Path) -> list[Path]:
    """No hand-off file: a robot stack must never pick up an older calibration next to a failed
    run's result."""
    path.unlink(missing_ok=True)
    return []


def write_calibration(run: CalibrationRun, folder: Path, name: str) -> list[Path]:
    """``calibration.yaml``, when an estimate is handed off."""
    doc = calibration_dict(run)
    if doc is None:
        return _none(folder / name)
    atomic_write_text(folder / name, calibration_yaml(doc))
    return [folder / name]


def write_joint(run: CalibrationRun, folder: Path, name: str, users: bool = False) -> list[Path]:
    """The URDF joint alone, when an estimate is handed off (``users``: the user's own joint)."""
    found = urdf_mount(run)
    if found is None:
        return _none(folder / name)
    atomic_write_text(folder / name, urdf_joint(run, *found, users=users))
    return [folder / name]


def write_users_robot(
    run: CalibrationRun, folder: Path, name: str, description: urdf.Description, link: str
) -> list[Path]:
    """The user's own robot description with ``link``'s joint re-posed, when an estimate is handed
    off (``run``'s mount placed in that description: :func:`nlp_calib.outputs.urdf.placed`)."""
    found = urdf_mount(run)
    if found is None:
        return _none(folder / name)
    atomic_write_bytes(folder / name, urdf.reposed(description, link, found[1]))
    return [folder / name]


def write_robot(run: CalibrationRun, folder: Path, name: str) -> list[Path]:
    """A complete robot description with the calibrated joint, when an estimate is handed off."""
    found = urdf_mount(run)
    if found is None:
        return _none(folder / name)
    atomic_write_text(folder / name, urdf_robot(run, *found))
    return [folder / name]

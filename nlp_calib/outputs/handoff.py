"""Hand-off files a robot stack reads directly: ``calibration.yaml`` and a URDF joint snippet.

"The" calibration is the first converged solver in the scenario's solver order; every solver's
estimate is kept under ``solvers:`` as well. Numbers are taken from the same document as
``result.json`` and written with full (repr) precision, so both files hold identical floats.
Nothing time-dependent is written: the same run gives the same bytes.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any
from xml.etree import ElementTree as ET

import yaml

from nlp_calib.core.errors import UsageError
from nlp_calib.core.files import atomic_write_bytes, atomic_write_text
from nlp_calib.core.version import __version__
from nlp_calib.outputs import urdf
from nlp_calib.outputs.results import result_document
from nlp_calib.results import CalibrationRun
from nlp_calib.results.handoff import MountPose

CALIBRATION_FILE = "calibration.yaml"
URDF_FILE = "sensor_mount.urdf.xml"
ROBOT_URDF_FILE = "robot.urdf"
PARENT_FRAME = "base_link"


def _solver_entry(res: Mapping[str, Any]) -> dict[str, Any]:
    keys = ("converged", "reason", "cost", "chi2", "inliers", "residuals", "iterations")
    return {
        **{k: res[k] for k in keys},
        "parameters": res["params"],
        "std": res["std"],
        "std_white_noise": res["std_white_noise"],
        "correlation": res["correlation"],
    }


def calibration_dict(run: CalibrationRun) -> dict[str, Any] | None:
    """The ``calibration.yaml`` document, or None when no estimate is handed off."""
    solver = run.handoff_solver()
    if solver is None:
        return None
    doc = result_document(run)
    best = doc["solvers"][solver]
    sc = run.scenario
    ds = doc["dataset"]
    return {
        "tool": {"name": "nlp_calib", "version": __version__},
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
        "frames": {"parent": PARENT_FRAME, "sensor": run.log.sensor_frame},
        "sensor": _sensor_entry(run, solver),
        "parameters": best["params"],
        "std": best["std"],
        "std_white_noise": best["std_white_noise"],
        "std_blocks": (doc["crossvalidation"] or {}).get("std_blocks"),
        # The jackknife σ's folds (its degrees of freedom + 1) and the formulation fitted: what
        # `nlp-calib check` needs to judge this calibration on a new log.
        "std_blocks_folds": len(run.checks.crossval.converged) if run.checks.crossval is not None else 0,
        "objective": {"residual": doc["residual"], "robust": doc["robust"]},
        "correlation": best["correlation"],
        "units": dict(sc.units),
        # The units "per t_max ticks" and "per tick" refer to these encoders' ranges.
        "encoders": [
            {"name": e.name, "kind": e.kind, "unit": e.unit, "ticks_per_turn": e.range}
            for e in run.log.encoders
        ],
        "verdict": {"level": run.verdict.level, "reasons": list(run.verdict.reasons)},
        "solvers": {name: _solver_entry(res) for name, res in doc["solvers"].items()},
    }


def _sensor_entry(run: CalibrationRun, solver: str) -> dict[str, Any]:
    """Which sensor the calibration holds the mount of, and that mount as a URDF joint."""
    info, mount = run.scenario.sensor, _mount(run, solver)
    return {
        "kind": info.kind,
        "group": info.group,
        "scale": info.scale,
        "params": list(info.params),
        "convention": info.convention,
        "held": {n: run.initial.get(n, 0.0) for n in info.held},
        "urdf": {"xyz": list(mount.xyz), "rpy": list(mount.rpy), "calibrated": mount.calibrated},
        # A mount per log: each log's own, one URDF joint each.
        **(
            {
                "mounts": [
                    {"log": m.log, "frame": m.frame, "xyz": list(m.mount.xyz), "rpy": list(m.mount.rpy)}
                    for m in run.reports[solver].mounts
                ]
            }
            if run.reports[solver].mounts
            else {}
        ),
    }


class _Dumper(yaml.SafeDumper):
    """Block mappings, but flow-style lists of scalars (matrix rows, record ranges)."""

    def ignore_aliases(self, data: Any) -> bool:
        return True  # repeated blocks are written out in full: no &anchors for readers to resolve


def _represent_list(dumper: yaml.SafeDumper, data: list[Any]) -> yaml.Node:
    flow = all(not isinstance(v, (list, dict)) for v in data)
    return dumper.represent_sequence("tag:yaml.org,2002:seq", data, flow_style=flow)


_Dumper.add_representer(list, _represent_list)


def calibration_yaml(doc: Mapping[str, Any]) -> str:
    """YAML text of a calibration document (a comment header, then the document)."""
    head = (
        f"# Wheeled-robot calibration by nlp_calib {doc['tool']['version']}, scenario "
        f"{doc['scenario']['name']}.\n"
        f"# 'parameters' are {doc['solver']}'s estimate ({doc['solver_choice']}); 'std' is the 1 sigma to\n"
        "# believe: the larger of 'std_white_noise' (white tracker and encoder noise only: a floor) and\n"
        "# 'std_blocks' (the spread of fits each without one block of the drive: every error that varies).\n"
        f"# {_mount_words(doc)}: pose of the '{doc['frames']['sensor']}' frame in "
        f"'{doc['frames']['parent']}'.\n"
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
    return text.replace("--", "- -")  # '--' may not appear inside an XML comment


def _joint(run: CalibrationRun, solver: str) -> ET.Element:
    return _joint_of(run.log.sensor_frame, _mount(run, solver))


def _joint_of(frame: str, mount: MountPose) -> ET.Element:
    joint = ET.Element("joint", {"name": f"{PARENT_FRAME}_to_{frame}", "type": "fixed"})
    ET.SubElement(joint, "parent", {"link": PARENT_FRAME})
    ET.SubElement(joint, "child", {"link": frame})
    ET.SubElement(joint, "origin", _origin(mount))
    return joint


def _joints(run: CalibrationRun, solver: str) -> list[tuple[str, ET.Element]]:
    """Each calibrated mount's frame and joint: the sensor's, or every log's own (a mount per log)."""
    every = run.reports[solver].mounts
    if every:
        return [(m.frame, _joint_of(m.frame, m.mount)) for m in every]
    return [(run.log.sensor_frame, _joint(run, solver))]


def _origin(mount: MountPose) -> dict[str, str]:
    """The joint's ``xyz`` and ``rpy``, as the sensor gives its mount."""
    return {"xyz": " ".join(repr(v) for v in mount.xyz), "rpy": " ".join(repr(a) for a in mount.rpy)}


def _mount(run: CalibrationRun, solver: str) -> MountPose:
    mount = run.reports[solver].mount
    if mount is None:
        raise UsageError(f"the result of {run.scenario.name} holds no mount for {solver}; run it again")
    return mount


def _xml(element: ET.Element, comment: str) -> str:
    ET.indent(element, space="  ")
    body = ET.tostring(element, encoding="unicode")
    return f'<?xml version="1.0"?>\n<!--{_comment_text(comment)}-->\n{body}\n'


def urdf_joint(run: CalibrationRun, solver: str) -> str:
    """A URDF ``<joint>`` placing the sensor frame on ``base_link`` with ``solver``'s estimate (a
    mount per log: a ``<robot>`` of one joint per log, each log's sensor its own link)."""
    what = _mount(run, solver).calibrated
    joints = _joints(run, solver)
    if len(joints) > 1:
        robot = ET.Element("robot", {"name": run.scenario.name})
        for _, joint in joints:
            robot.append(joint)
        links = ", ".join(f"'{frame}'" for frame, _ in joints)
        comment = (
            f" Sensor mounting poses calibrated by nlp_calib {__version__}: scenario {run.scenario.name}, "
            f"solver {solver}, one per log ({', '.join(m.log for m in run.reports[solver].mounts)}). "
            f"Calibrated: {what}. Paste these joints into the robot's <robot> description; the links "
            f"{links} must be declared there. "
        )
        return _xml(robot, comment)
    frame = run.log.sensor_frame
    comment = (
        f" Sensor mounting pose calibrated by nlp_calib {__version__}: scenario {run.scenario.name}, "
        f"solver {solver}. Calibrated: {what}. Paste this joint into the robot's <robot> description; "
        f"the link '{frame}' must be declared there. "
    )
    return _xml(_joint(run, solver), comment)


def urdf_robot(run: CalibrationRun, solver: str) -> str:
    """A complete URDF: a ``<robot>`` with ``base_link``, the sensor's link and the calibrated joint."""
    robot = ET.Element("robot", {"name": run.scenario.name})
    ET.SubElement(robot, "link", {"name": PARENT_FRAME})
    joints = _joints(run, solver)
    for frame, _ in joints:
        ET.SubElement(robot, "link", {"name": frame})
    for _, joint in joints:
        robot.append(joint)
    comment = (
        f" The sensor mount calibrated by nlp_calib {__version__}: scenario {run.scenario.name}, "
        f"solver {solver}. A complete robot description (base and sensor links, the fixed joint) "
        f"that URDF tools load as it is; {URDF_FILE} holds the joint alone for pasting. "
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


def write_joint(run: CalibrationRun, folder: Path, name: str) -> list[Path]:
    """The URDF joint alone, when an estimate is handed off."""
    solver = run.handoff_solver()
    if solver is None:
        return _none(folder / name)
    atomic_write_text(folder / name, urdf_joint(run, solver))
    return [folder / name]


def write_users_robot(
    run: CalibrationRun, folder: Path, name: str, description: urdf.Description, link: str
) -> list[Path]:
    """The user's own robot description with ``link``'s joint re-posed, when an estimate is handed off."""
    solver = run.handoff_solver()
    if solver is None:
        return _none(folder / name)
    mount = _mount(run, solver)
    roll, pitch, yaw = mount.rpy
    # The user's own height is kept, and their roll and pitch where the sensor calibrated neither.
    tilt = (roll, pitch) if mount.tilted else None
    text = urdf.reposed(description, link, mount.xyz[0], mount.xyz[1], yaw, tilt)
    atomic_write_bytes(folder / name, text)
    return [folder / name]


def write_robot(run: CalibrationRun, folder: Path, name: str) -> list[Path]:
    """A complete robot description with the calibrated joint, when an estimate is handed off."""
    solver = run.handoff_solver()
    if solver is None:
        return _none(folder / name)
    atomic_write_text(folder / name, urdf_robot(run, solver))
    return [folder / name]

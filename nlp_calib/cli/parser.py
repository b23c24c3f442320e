"""The command line's grammar: subcommands, options and their help."""

from __future__ import annotations

import argparse
import functools
import re
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, NoReturn

from nlp_calib.core.errors import FieldError, UsageError
from nlp_calib.core.ranges import Range, check_ros_name
from nlp_calib.core.text import escaped
from nlp_calib.core.version import __version__
from nlp_calib.logs.bag_reader import CLOCK_OFFSET, DEFAULT_MAX_GAP_S, JOINT_UNITS, MAX_GAP, TRACKER_TYPES
from nlp_calib.models import DEFAULT_MODEL, MODELS, encoders
from nlp_calib.outputs.ros2_control import DEFAULT_ROS_DISTRO, ROS_DISTROS
from nlp_calib.pipeline.options import BLOCKS
from nlp_calib.solvers import SOLVERS

#: ``--solver`` values that mean every registered solver.
ALL_SOLVERS = ("all", "both")


#: ``odometry --sigma``: the size of the drawn covariance ellipses, in standard deviations.
SIGMA = Range(0.0, 10.0, lo_open=True)
#: ``batch --jobs``: worker processes.
JOBS = Range(1, 256, integer=True)


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> NoReturn:
        raise UsageError(f"{message} (see '{self.prog} --help')")

    def parse_known_args(  # type: ignore[override]
        self, args: Sequence[str] | None = None, namespace: argparse.Namespace | None = None
    ) -> tuple[argparse.Namespace, list[str]]:
        parsed, extra = super().parse_known_args(args, namespace)
        # argparse drops a value "--" ("--records=--") and stores an empty list without calling
        # the option's type: no value at all.
        for action in self._actions:
            if action.nargs is None and action.option_strings and getattr(parsed, action.dest, None) == []:
                limit = getattr(action.type, "limit", None)
                expected = f"must be {limit.describe()}" if limit is not None else "expected a value"
                self.error(f"argument {'/'.join(action.option_strings)}: {expected}, got none")
        return parsed, extra


def _path(text: str) -> Path:
    """A path option: not empty (``--out ""`` would mean the current folder), no NUL."""
    if not text or "\0" in text:
        raise argparse.ArgumentTypeError(f"expected a path, got {text!r}")
    return Path(text)


#: Scheduler address forms Dask reaches over a network; a host name or address, and a port.
DASK_SCHEMES = ("tcp", "tls", "ws", "wss", "ucx")
_HOST = re.compile(r"(?:[A-Za-z0-9](?:[A-Za-z0-9-]{0,61}[A-Za-z0-9])?\.?)+|\[[0-9A-Fa-f:.]+\]")
DASK_FORM = "tcp://HOST:PORT (or tls://, ws://, wss://, ucx://; HOST a name or address, PORT 1-65535)"


def dask_address(text: str) -> str:
    """``--dask``: a scheduler's address, checked before Dask sees it (Dask reads many strings as
    something else: a path, an in-process scheduler, a port it never reaches). Never echoes
    credentials."""
    scheme, sep, rest = text.partition("://")
    if not sep:
        scheme, rest = "tcp", text
    if "@" in rest:  # user:password@host: said without the text, which would show the password
        raise argparse.ArgumentTypeError(
            f"the address holds credentials (user:password@), which Dask does not take and this "
            f"message does not repeat; give {DASK_FORM}"
        )
    shown_text = escaped(text if len(text) <= 80 else f"{text[:60]}… ({len(text)} characters)")
    host, colon, port = rest.rpartition(":")
    ok = (
        scheme.lower() in DASK_SCHEMES
        and colon
        and len(host) <= 253
        and _HOST.fullmatch(host) is not None
        and port.isascii()
        and port.isdigit()
        and 1 <= int(port[:6]) <= 65535
    )
    if not ok:
        raise argparse.ArgumentTypeError(f"expected a scheduler address {DASK_FORM}, got '{shown_text}'")
    return text


def _names(text: str) -> tuple[str, ...]:
    """A comma-separated list of names, none empty."""
    names = tuple(n.strip() for n in text.split(","))
    if not all(names):
        raise argparse.ArgumentTypeError(f"expected names separated by commas, got {text!r}")
    return names


def _ros_name(text: str) -> str:
    """A ROS 2 node name (it becomes a YAML key)."""
    try:
        check_ros_name("", text)
    except FieldError as exc:
        raise argparse.ArgumentTypeError(exc.reason) from None
    return text


def _in(limit: Range) -> Callable[[str], int | float]:
    """An option type that accepts numbers in ``limit`` and names the range otherwise."""

    def parse(text: str) -> int | float:
        try:
            return limit.parse(text)
        except ValueError as exc:
            raise argparse.ArgumentTypeError(str(exc)) from None

    parse.__name__ = "number"
    parse.limit = limit  # type: ignore[attr-defined]
    return parse


def _add_force(p: argparse.ArgumentParser, what: str) -> None:
    p.add_argument("--force", action="store_true", help=f"overwrite {what} that nlp_calib did not write")


EXIT_CODES = (
    "exit codes: 0 success; 1 a solver did not converge or the run failed; 2 bad input (scenario, log, "
    "options: nothing is computed); 4, 5 (run, compare, odometry) the pre-flight found that the drive "
    "cannot determine a parameter (4) or that the data get a unit or sign wrong (5): nothing is fitted "
    "(see 'nlp-calib preflight'); 130, 143, 129 interrupted by SIGINT, SIGTERM, SIGHUP (the output "
    "folder keeps the previous run's files)"
)

#: One or two example command lines per subcommand, shown by its --help.
EXAMPLES: dict[str, tuple[str, ...]] = {
    "run": (
        "nlp-calib run scenarios/demo.yaml",
        "nlp-calib run scenarios/real_tricycle.yaml --data /path/to/dataset.txt --report",
    ),
    "compare": (
        "nlp-calib compare scenarios/demo.yaml --report",
        "nlp-calib compare scenarios/real_tricycle.yaml scenarios/real_tricycle_seed.yaml "
        "--data /path/to/dataset.txt",
    ),
    "validate": ("nlp-calib validate scenarios/demo.yaml --blocks 10",),
    "odometry": ("nlp-calib odometry scenarios/demo.yaml --report --sigma 3",),
    "codegen": ("nlp-calib codegen scenarios/demo.yaml --out c_export && make -C c_export example",),
    "simulate": (
        "nlp-calib simulate --out my_drive.txt --records 2000 --seed 3 --latency 0.05",
        "nlp-calib simulate --lidar --out lidar_drive --duration 120",
        "nlp-calib simulate --imu --out gyro_drive --duration 120 --latency 0.02",
        "nlp-calib simulate --lidar --imu --out lidar_gyro_drive --duration 60",
        "nlp-calib simulate --vehicle highway_car --out highway --seed 31",
    ),
    "check": (
        "nlp-calib check out/demo/calibration.yaml todays_drive.txt",
        "nlp-calib check out/real/calibration.yaml scenarios/real_tricycle.yaml --out out/check_today",
    ),
    "batch": (
        "nlp-calib batch logs/ --scenario scenarios/demo.yaml --out out/fleet --jobs 2",
        "nlp-calib batch 'logs/**/drive*.txt' --check out/demo/calibration.yaml --out out/nightly",
    ),
    "preflight": (
        "nlp-calib preflight scenarios/demo.yaml",
        "nlp-calib preflight drive_ros2/ --json preflight.json",
    ),
    "init": ("nlp-calib init drive_ros2/ --out my_robot.yaml",),
    "import-bag": (
        f"nlp-calib import-bag drive.bag --out drive.txt --model {DEFAULT_MODEL} --joint-states "
        "/joint_states --joints steer_joint,drive_joint --tracker /mocap/robot/pose",
        f"nlp-calib import-bag drive_ros2/ --out drive.txt --model {DEFAULT_MODEL} --joint-states "
        "/joint_states --joints steer_joint,drive_joint --tracker /tf --tracker-frame robot "
        "--robot robot.yaml",
    ),
}


#: Commands whose exit codes say more than success or failure.
COMMAND_EXIT_CODES = {
    "preflight": (
        "exit codes: 0 enough: the drive determines every parameter; 3 weak: a parameter only weakly (a run "
        "ends usable with caveats); 4 not enough: the drive cannot determine a parameter (the report says "
        "which, why and what to drive); 5 check the data: units or signs the data get wrong (degrees, a "
        "wrapped wheel angle, a mirrored wheel); 1 the check failed; 2 bad input; 130, 143, 129 interrupted"
    ),
    "check": (
        "exit codes: 0 still good; 3 drifted: recalibrate (the verdict names what moved and by how much); "
        "4 cannot tell (the log cannot test a parameter: the verdict says what to drive); 1 the run failed; "
        "2 bad input (calibration, scenario, log, options: nothing is computed); 130, 143, 129 interrupted "
        "by SIGINT, SIGTERM, SIGHUP (the output folder keeps the previous files)"
    ),
    "batch": (
        "exit codes: 0 every log succeeded (with --check: and every one is still good); 1 a log failed (its "
        "row in summary.csv says why; the others ran); with --check, every log ran and: 3 a log drifted, 4 "
        "none drifted but a log could not tell; 2 bad input (nothing is computed); 130, 143, 129 interrupted "
        "by SIGINT, SIGTERM, SIGHUP (the folders of the logs that finished stay; no summary is written)"
    ),
}


def _epilog(command: str) -> str:
    lines = "\n".join(f"  {e}" for e in EXAMPLES[command])
    codes = COMMAND_EXIT_CODES.get(command, EXIT_CODES)
    return f"example{'s' if len(EXAMPLES[command]) > 1 else ''}:\n{lines}\n\n{codes}"


def _add_common(p: argparse.ArgumentParser, report: str | None) -> None:
    p.add_argument(
        "scenario", type=Path, nargs="+", help="scenario YAML file(s); several are summarised side by side"
    )
    p.add_argument(
        "--out",
        type=_path,
        default=None,
        help="output folder (default: out/<scenario name>; with several scenarios, DIR/<scenario name>)",
    )
    p.add_argument(
        "--data",
        type=_path,
        action="append",
        default=None,
        metavar="PATH|NAME=PATH",
        help="log file to use instead of the scenario's dataset; with several scenarios, either all of "
        "them name the same dataset, or give NAME=PATH once per scenario to replace",
    )
    if report is not None:
        p.add_argument("--report", action="store_true", help=report)
    _add_force(p, "files in the output folder")
    if report is not None:  # the calibrating commands (validate cross-validates whatever it is given)
        _add_skip_preflight(p)


def _add_skip_preflight(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--skip-preflight",
        action="store_true",
        help="calibrate even when the pre-flight finds that the drive cannot determine a parameter or that "
        "the data get a unit or sign wrong",
    )


def _add_handoff(p: argparse.ArgumentParser) -> None:
    """The options of the hand-off files: the user's URDF, the sensor's link in it, the ROS release."""
    p.add_argument(
        "--urdf",
        type=_path,
        default=None,
        help="your robot's URDF: robot.urdf is written as that file with the sensor's joint re-posed "
        "(x, y, yaw calibrated; z, roll, pitch and everything else kept), and sensor_mount.urdf.xml "
        "holds that same joint; needs --sensor-link",
    )
    p.add_argument(
        "--sensor-link",
        default=None,
        metavar="LINK",
        help="the sensor's link in --urdf (the child of the joint to re-pose)",
    )
    p.add_argument(
        "--controller-name",
        type=_ros_name,
        default=None,
        metavar="NAME",
        help="your ros2_control controller's name (its key under controller_manager, e.g. "
        "diffbot_base_controller): the top key of ros2_control.yaml (default: the scenario's "
        "handoff.controller_name, else the controller's type, with a first line saying to rename it)",
    )
    p.add_argument(
        "--ros-distro",
        choices=ROS_DISTROS,
        default=DEFAULT_ROS_DISTRO,
        help=f"the ROS 2 release whose ros2_controllers' parameter names ros2_control.yaml uses "
        f"(default: {DEFAULT_ROS_DISTRO})",
    )


REPORT = (
    "also draw the trajectory, convergence, residual and model-check figures, report.md and trajectories/"
)


def _sub(command: str) -> dict[str, Any]:
    return {"epilog": _epilog(command), "formatter_class": argparse.RawDescriptionHelpFormatter}


def named_command(argv: Sequence[str]) -> str | None:
    """The command ``argv`` names: its first word that is not an option (the program's own options
    take no value); None when there is none."""
    return next((a for a in argv if not a.startswith("-")), None)


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The command line's grammar. ``command``: the one the arguments name (None: any), whose
    grammar alone is read: ``simulate``'s options, which load the simulator, are added only for it
    (its help line always)."""
    parser = _Parser(
        prog="nlp-calib",
        description="Calibrate a wheeled robot's kinematics and sensor mounting pose.",
        epilog=f"example:\n  nlp-calib compare scenarios/demo.yaml --report\n\n{EXIT_CODES}",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--version", action="version", version=f"nlp_calib {__version__}")
    parser.add_argument("--debug", action="store_true", help="show tracebacks on errors")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)
    for add in (
        _add_run,
        _add_compare,
        _add_validate,
        _add_codegen,
        _add_odometry,
        functools.partial(_add_simulate, options=command in (None, "simulate")),
        _add_import_bag,
        _add_check,
        _add_batch,
        _add_preflight,
        _add_init,
    ):
        add(sub)
    return parser


def _add_run(sub: Any) -> None:
    p = sub.add_parser("run", help="calibrate with the scenario's solvers (or --solver)", **_sub("run"))
    _add_common(p, REPORT)
    _add_handoff(p)
    p.add_argument(
        "--solver",
        choices=(*SOLVERS, *ALL_SOLVERS),
        default=None,
        help="solver to run (default: the scenario's solvers; 'all' or 'both': every solver)",
    )


def _add_compare(sub: Any) -> None:
    p = sub.add_parser("compare", help="calibrate with every solver, side by side", **_sub("compare"))
    _add_common(p, REPORT)
    _add_handoff(p)


def _add_validate(sub: Any) -> None:
    p = sub.add_parser(
        "validate",
        help="cross-validate on contiguous blocks: fit without each block, score it, compare the σ",
        **_sub("validate"),
    )
    _add_common(p, None)
    p.add_argument(
        "--blocks",
        type=_in(BLOCKS),
        default=None,
        help="contiguous blocks (default: validation.blocks, else 10)",
    )


def _add_codegen(sub: Any) -> None:
    p = sub.add_parser(
        "codegen", help="write C source and header of the residual and its Jacobian", **_sub("codegen")
    )
    p.add_argument("scenario", type=Path, help="scenario YAML file (model, horizon, integration)")
    p.add_argument("--out", type=_path, required=True, help="folder for the C files")
    p.add_argument(
        "--data", type=_path, default=None, help="log file to use instead of the scenario's dataset"
    )
    _add_force(p, "files in the output folder")


def _add_odometry(sub: Any) -> None:
    p = sub.add_parser(
        "odometry",
        help="calibrate, then write the base-link odometry with its propagated covariance",
        **_sub("odometry"),
    )
    _add_common(p, "also draw odometry.png: the odometry with its σ ellipses against the tracker")
    _add_handoff(p)
    p.add_argument(
        "--solver",
        choices=tuple(SOLVERS),
        default=next(iter(SOLVERS)),
        help=f"the solver whose calibration drives the odometry (default: {next(iter(SOLVERS))})",
    )
    p.add_argument(
        "--sigma",
        type=_in(SIGMA),
        default=3.0,
        help=f"ellipse size in σ for --report, {SIGMA.describe()} (default 3)",
    )


def _add_simulate(sub: Any, options: bool = True) -> None:
    p = sub.add_parser(
        "simulate", help="write a synthetic log with known truth (truth JSON beside it)", **_sub("simulate")
    )
    if options:
        _add_simulate_options(p)


def _add_simulate_options(p: argparse.ArgumentParser) -> None:
    # The simulator's tables, loaded here: a command other than simulate never needs them.
    from nlp_calib.pipeline.simconfig import CLI_LIMITS
    from nlp_calib.simulation import TRAJECTORIES

    p.add_argument(
        "--out",
        type=_path,
        required=True,
        help="log file to write; a path ending in .tum writes a tilted camera's TUM trajectory with "
        "<name>.joints.csv (joints in radians) and <name>.truth.json beside it (docs/camera.md)",
    )
    _add_force(p, "an existing log or truth file")
    _add_simulated_kinds(p)
    p.add_argument("--config", type=_path, default=None, help="YAML file of simulation options")
    p.add_argument("--model", choices=tuple(MODELS), default=None, help=f"default: {next(iter(MODELS))}")
    p.add_argument(
        "--trajectory",
        choices=TRAJECTORIES,
        default=None,
        help="s_curves: turns, stops and reversals (default); straight: no turning; no_reversals; "
        "circles: constant speed, turning one way then the other",
    )
    for flag, field, what in (
        ("--records", "records", "records to write"),
        ("--seed", "seed", "random seed"),
        ("--noise-xy", "tracker_noise_xy", "tracker noise, m"),
        ("--noise-theta", "tracker_noise_theta", "tracker noise, rad"),
        ("--outliers", "outlier_fraction", "fraction of outliers"),
        ("--latency", "latency_s", "tracker latency, s (a camera's stamp offset)"),
        ("--duration", "duration_s", "seconds of driving (a camera, lidar or gyro simulation)"),
    ):
        limit = CLI_LIMITS[field]
        p.add_argument(flag, type=_in(limit), default=None, dest=field, help=f"{what}: {limit.describe()}")


def _add_simulated_kinds(p: argparse.ArgumentParser) -> None:
    """What ``simulate`` writes other than a text log: a lidar's, a gyro's, a vehicle's, a vendor's."""
    from nlp_calib.simulation.vehicles import VEHICLES

    kind = p.add_mutually_exclusive_group()
    kind.add_argument(
        "--lidar",
        action="store_true",
        help="a 2-D lidar in a room of walls: a ROS 2 bag (folder --out) of /scan, /joint_states and "
        "/tf_static, and --out.truth.json (docs/lidar.md); --outliers: the share of degraded scans; "
        "--latency: how late its driver stamps the scans",
    )
    p.add_argument(
        "--imu",
        action="store_true",
        help="a tilted gyro with a bias: a ROS 2 bag (folder --out) of /imu, /joint_states and /tf_static, "
        "and --out.truth.json (docs/imu.md); --latency: how late its driver stamps the rates; with "
        "--lidar: both on one drive in one bag, both drivers stamping --latency late",
    )
    p.add_argument(
        "--tracker",
        action="store_true",
        help="with --imu: a tracker's poses (/tracker, PoseStamped, 2 mm and 2 mrad of noise) of the drive "
        "in the same bag, stamped --latency late as the gyro is (docs/imu.md)",
    )
    kind.add_argument(
        "--vehicle",
        choices=tuple(VEHICLES),
        default=None,
        help=(
            "a real vehicle's drive (--out: the stem of its files; docs/models.md): highway_car, a car at "
            "8-20 m/s for a minute barely turning, four CAN wheel speeds and its steer angle at 90 Hz "
            "(<out>.csv) beside a windshield device's poses at 20 Hz (<out>.tum); skid_spins, a skid-steer "
            "spinning over pi per 2 s increment, its encoders updating at 4 Hz under 20 Hz messages and "
            "slipping on pivots (<out>.csv), against a scan matcher's increments (<out>.motions.csv); "
            "--seed, --duration and (a skid-steer's matcher) --noise-xy, --noise-theta; the rest in --config"
        ),
    )
    kind.add_argument(
        "--vendor",
        action="store_true",
        help="a robot's own odometry integrated with a wrong model (--out: t x y θ), a tracker's TUM file "
        "beside it and the corrections in the truth JSON (docs/vendor.md)",
    )


def _add_import_bag(sub: Any) -> None:
    p = sub.add_parser(
        "import-bag",
        help="convert a ROS 1 or ROS 2 bag (joints and tracker) into a CSV joint log and a TUM file, or a "
        "text log of raw counts (docs/bags.md)",
        **_sub("import-bag"),
    )
    orders = "; ".join(f"{name}: {','.join(encoders(m))}" for name, m in MODELS.items())
    p.add_argument("bag", type=_path, help="a ROS 1 .bag file or a ROS 2 bag folder (sqlite3 or MCAP)")
    p.add_argument(
        "--out",
        type=_path,
        required=True,
        help="joint log (.csv; the tracker beside it as .tum) or text log to write",
    )
    _add_force(p, "an existing log")
    p.add_argument("--model", choices=tuple(MODELS), required=True, help="the robot's kinematic model")
    p.add_argument(
        "--joint-states",
        default=None,
        metavar="TOPIC",
        help="sensor_msgs/msg/JointState topic with the joints' positions (or velocities); default: the "
        "bag's only one (else the bag's topics are listed)",
    )
    p.add_argument(
        "--joints",
        type=_names,
        default=None,
        metavar="NAME,NAME",
        help=f"the JointState joints in the model's encoder order ({orders}); default: those whose names "
        "say which encoder they are (else the joints found are listed)",
    )
    p.add_argument(
        "--tracker",
        default=None,
        metavar="TOPIC",
        help=f"the tracked sensor's poses: {', '.join(TRACKER_TYPES)}; default: the bag's only one",
    )
    p.add_argument(
        "--tracker-frame",
        default=None,
        metavar="CHILD",
        help="child frame of the tracked sensor's transforms (required on a TFMessage topic)",
    )
    p.add_argument(
        "--robot",
        type=_path,
        default=None,
        metavar="ROBOT.yaml",
        help="initial guess, encoder ranges, nominal sensor pose for the header (default: the model's)",
    )
    p.add_argument(
        "--max-gap",
        type=_in(MAX_GAP),
        default=DEFAULT_MAX_GAP_S,
        metavar="S",
        help=f"longest gap of one topic the other's time is interpolated across, {MAX_GAP.describe()} s "
        f"(default {DEFAULT_MAX_GAP_S:g})",
    )
    _add_import_timing(p)


def _add_import_timing(p: Any) -> None:
    p.add_argument(
        "--joint-units",
        choices=JOINT_UNITS,
        default="radians",
        help="what JointState.position holds: radians (REP 103, the default: writes the joints as a CSV "
        "joint log and the tracker as a TUM file) or raw counts (writes a text log)",
    )
    p.add_argument(
        "--stamps",
        action="append",
        default=None,
        metavar="[TOPIC=]header|receive",
        help="time a topic (or both) by the bag's record times instead of its header stamps",
    )
    p.add_argument(
        "--clock-offset",
        type=_offset,
        default=0.0,
        metavar="S|auto",
        help="seconds added to the joints' stamps (another clock), or auto to estimate it from record times",
    )


def _offset(text: str) -> float | str:
    if text == "auto":
        return text
    value = _in(CLOCK_OFFSET)(text)
    return float(value)


def _add_check(sub: Any) -> None:
    p = sub.add_parser(
        "check",
        help="is a calibration still good on a new log? each parameter's change in its σ, and a verdict",
        **_sub("check"),
    )
    p.add_argument(
        "calibration", type=_path, metavar="CALIBRATION.yaml", help="a calibration.yaml nlp-calib wrote"
    )
    p.add_argument(
        "target",
        type=_path,
        metavar="SCENARIO|LOG",
        help="a scenario (.yaml) of the new log, or the log itself (read with the scenario the calibration "
        "records, else the model's defaults and the recorded residual)",
    )
    p.add_argument("--out", type=_path, default=None, help="output folder (default: out/check_<log name>)")
    _add_force(p, "files in the output folder")


def _add_batch(sub: Any) -> None:
    p = sub.add_parser(
        "batch",
        help="calibrate (or --check) many logs or scenarios: one folder each and a summary table",
        **_sub("batch"),
    )
    p.add_argument(
        "inputs",
        nargs="+",
        metavar="FOLDER|GLOB|LIST.yaml|FILE",
        help="logs and scenarios: a folder (its logs), a quoted glob, a YAML list of paths, or files",
    )
    p.add_argument(
        "--out", type=_path, default=Path("out") / "batch", help="output folder (default: out/batch)"
    )
    p.add_argument("--scenario", type=_path, default=None, help="the scenario each log is calibrated with")
    p.add_argument(
        "--model", choices=tuple(MODELS), default=None, help="without --scenario: the model (its defaults)"
    )
    p.add_argument(
        "--check", type=_path, default=None, metavar="CALIBRATION.yaml", help="check each log against it"
    )
    p.add_argument(
        "--solver", choices=tuple(SOLVERS), default=None, help="the solver (default: the scenario's)"
    )
    p.add_argument(
        "--jobs",
        type=_in(JOBS),
        default=None,
        help=f"logs at once at most, {JOBS.describe()} (default: the cores); never more than the cores free",
    )
    p.add_argument(
        "--dask",
        type=dask_address,
        default=None,
        metavar="ADDRESS",
        help="run the logs on the Dask cluster whose scheduler is there (tcp://HOST:8786; "
        "the fleet extra); every worker must see --out",
    )
    p.add_argument("--report", action="store_true", help=REPORT)
    _add_force(p, "files in the output folders")


def _add_preflight(sub: Any) -> None:
    p = sub.add_parser(
        "preflight",
        help="before any fit: what a recording holds, the drive, units and signs, and whether it determines "
        "each parameter (and what to drive next)",
        **_sub("preflight"),
    )
    p.add_argument(
        "target",
        type=_path,
        metavar="LOG|BAG|SCENARIO",
        help="a scenario (.yaml), or a recording: a text log, a ROS bag, a joint log's .csv or .tum (its "
        "scenario drafted as 'nlp-calib init' drafts it)",
    )
    p.add_argument(
        "--model", choices=tuple(MODELS), default=None, help="for a recording: the model (default: guessed)"
    )
    p.add_argument("--json", type=_path, default=None, metavar="FILE", help="also write the report as JSON")
    _add_force(p, "a --json file")


def _add_init(sub: Any) -> None:
    p = sub.add_parser(
        "init",
        help="draft a commented scenario that run accepts from a recording (ROS bag, joint log, text log)",
        **_sub("init"),
    )
    p.add_argument("recording", type=_path, metavar="BAG|JOINTS.csv|POSES.tum|LOG", help="the recording")
    p.add_argument(
        "--out", type=_path, default=None, help="the scenario to write (default: <recording>.yaml)"
    )
    p.add_argument(
        "--model", choices=tuple(MODELS), default=None, help="the model (default: guessed from the joints)"
    )
    p.add_argument(
        "--robot",
        type=_path,
        default=None,
        metavar="ROBOT.yaml",
        help="the robot's nominal values (a joint log's): its track tells a skidding base (docs/bags.md)",
    )
    _add_force(p, "an existing scenario file")

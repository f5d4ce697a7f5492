"""Run a program through LinuxCNC's own task, interpreter, trajectory planner and servo loop, headless.

:func:`simulate` exports the machine's configuration (:func:`..export.export_config`, the files a
user runs) into a temporary directory and starts LinuxCNC there as its launcher would, without a
display: ``linuxcncsvr``, ``io``, ``tpmod``, ``homemod``, ``verne.hal`` (trivkins, motmod), a
HAL ``sampler`` in the servo thread after the motion controller, ``milltask``. The program runs
through the ``linuxcnc`` Python module; ``halsampler`` writes every servo period's commanded
joint positions (``joint.N.pos-cmd``) and the line being executed (``motion.program-line``).

The ``linuxcnc`` module exists for the system Python only, so that part is a small driver script
run with ``/usr/bin/python3``. The driver makes itself a child subreaper (``prctl``), so that
every process LinuxCNC starts (``linuxcncsvr`` daemonises, ``halcmd`` leaves ``rtapi_app``, ``io``
and ``milltask`` behind) stays its descendant: all are stopped by their PID, never by name. Where
it may (root, as in CI), it runs in a System V IPC namespace of its own, so LinuxCNC's fixed NML
and HAL shared memory keys meet no other LinuxCNC and vanish with it; elsewhere the segments and
semaphores are removed by key afterwards. ``rtapi_app`` refuses to run as root: as root the
driver sets ``RTAPI_UID`` to ``nobody``'s uid. Runs are serialised by a lock file.

Time scale K runs the motion K times faster in wall-clock time and reports it at K = 1: the
configuration's velocities times K, accelerations times K^2, servo period / K, the program's F
words times K (dwells / K); the samples are then one K = 1 servo period (1 ms) apart. Above
K = 5 the results drift (the servo thread of a non-realtime kernel cannot keep up).
"""

from __future__ import annotations

import fcntl
import json
import math
import os
import re
import shutil
import subprocess
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import InputError, UserError
from ..machine import Machine
from .export import HAL_NAME, SERVO_PERIOD_NS, export_config

__all__ = ["SYSTEM_PYTHON", "SimulationResult", "header_cycle_time", "linuxcnc_available", "simulate"]

#: The Python that has LinuxCNC's ``linuxcnc`` module (Debian's ``python3-linuxcnc`` files of linuxcnc-uspace).
SYSTEM_PYTHON = "/usr/bin/python3"
#: The programs a run needs (all in Debian's linuxcnc-uspace).
PROGRAMS = ("linuxcncsvr", "milltask", "io", "halcmd", "halsampler", "rtapi_app")
#: Serialises runs of this module on one machine.
LOCK_FILE = Path(tempfile.gettempdir()) / "verne-post-linuxcnc.lock"
_MISSING = ("LinuxCNC is not installed: simulate needs Debian's package linuxcnc-uspace "
            "(apt-get install linuxcnc-uspace)")


@dataclass(frozen=True, eq=False)
class SimulationResult:
    """Servo samples of a program as LinuxCNC ran it, at time scale 1.

    ``t`` (S,) s from the sample before the first motion; ``joints`` (S, 5) commanded joint
    positions, rho1..3 mm and theta1, theta2 rad; ``cycle_time`` s from the first motion to the
    last; ``line`` (S,) the program line being executed (LinuxCNC's ``motion.program-line``, 0
    between moves; empty if not recorded); ``errors``: LinuxCNC's messages during the run;
    ``period`` s between samples (1 ms).
    """

    t: np.ndarray
    joints: np.ndarray
    cycle_time: float
    line: np.ndarray
    errors: tuple[str, ...] = ()
    period: float = SERVO_PERIOD_NS * 1e-9


def linuxcnc_available() -> str | None:
    """None if LinuxCNC can run here, else the one-line reason."""
    if not all(shutil.which(program) for program in PROGRAMS):
        return _MISSING
    if not os.access(SYSTEM_PYTHON, os.X_OK):
        return _MISSING
    check = subprocess.run([SYSTEM_PYTHON, "-c", "import linuxcnc, hal"], capture_output=True, timeout=60)
    return None if check.returncode == 0 else _MISSING


_NUMBER = r"[-+]?(?:\d+\.?\d*|\.\d+)"
_COMMENT = re.compile(r"\([^)]*\)|;.*$")
_WORD = re.compile(rf"([A-Za-z])\s*({_NUMBER})")


def _code(line: str) -> str:
    return _COMMENT.sub(lambda m: " " * len(m.group(0)), line)


def first_position(text: str, letters: tuple[str, ...]) -> np.ndarray | None:
    """The first joint position (mm, degrees) at which all five axis words have been given, from
    the program's text; None if there is none."""
    known: dict[str, float] = {}
    for line in text.splitlines():
        for letter, value in _WORD.findall(_code(line)):
            if letter.upper() in letters:
                known[letter.upper()] = float(value)
        if len(known) == 5:
            return np.array([known[letter] for letter in letters])
    return None


def scaled_program(text: str, scale: float) -> str:
    """The program with its F words times ``scale`` and its dwells (G4 P) divided by it, comments kept."""
    if scale == 1.0:
        return text
    out = []
    for line in text.splitlines(keepends=True):
        code = _code(line)
        dwell = re.search(r"\bG0*4(?![\d.])", code, re.IGNORECASE) is not None
        pieces, position = [], 0
        for match in _WORD.finditer(code):
            letter = match.group(1).upper()
            if letter == "F" or (dwell and letter == "P"):
                value = float(match.group(2))
                value = value * scale if letter == "F" else value / scale
                pieces += [line[position:match.start()], f"{match.group(1)}{value:.10g}"]
                position = match.end()
        out.append("".join(pieces) + line[position:])
    return "".join(out)


def _header_cycle_time(text: str) -> float | None:
    match = re.search(r"CYCLE TIME (\d+(?:\.\d*)?) S\b", text)
    return float(match.group(1)) if match else None


def simulate(program_path: str | Path, machine: Machine, *, time_scale: float = 1.0,
             home: tuple[float, ...] | np.ndarray | None = None, timeout: float | None = None) -> SimulationResult:
    """Run the G-code program through LinuxCNC headless and return its servo samples (module doc).

    ``home``: the joint position (mm, degrees) LinuxCNC homes at (default: the program's first
    position). ``timeout``: wall-clock seconds before the run is stopped (default: from the
    header's cycle time). Raises :class:`InputError` without LinuxCNC, :class:`UserError` when
    LinuxCNC reports an error or the run does not finish.
    """
    if not (isinstance(time_scale, (int, float)) and math.isfinite(time_scale) and 0.01 <= time_scale <= 100):
        raise InputError(f"time scale {time_scale!r} is out of range (0.01 to 100)")
    source = str(program_path)
    try:
        text = Path(program_path).read_text(encoding="utf-8", errors="replace")
    except OSError as error:
        raise InputError(f"cannot read the program: {error.strerror or error}", source) from None
    reason = linuxcnc_available()
    if reason is not None:
        raise InputError(reason)
    letters = tuple(letter.upper() for letter in machine.controller.profile().axes)
    if home is None:
        home = first_position(text, letters)
    tools = {int(n): float(length) for n, length in re.findall(rf"\(TOOL (\d+) LENGTH ({_NUMBER})", text)}
    tools.update({int(n): 0.0 for n in re.findall(r"\bT\s*(\d+)", "\n".join(_code(x) for x in text.splitlines()))
                  if int(n) not in tools})
    planned = _header_cycle_time(text)
    if timeout is None:
        timeout = 120.0 + 3.0 * (planned if planned is not None else 3600.0) / time_scale
    with tempfile.TemporaryDirectory(prefix="verne-linuxcnc-") as temporary:
        folder = Path(temporary)
        os.chmod(folder, 0o755)
        ini = export_config(machine, folder, home=home, time_scale=time_scale, tools=tools)
        (folder / "sample.hal").write_text(_SAMPLER_HAL, encoding="utf-8")
        program = folder / "program.ngc"
        program.write_text(scaled_program(text, float(time_scale)), encoding="utf-8")
        fifo = folder / "rtapi"
        fifo.mkdir()
        os.chmod(fifo, 0o1777)
        driver = folder / "driver.py"
        driver.write_text(_DRIVER, encoding="utf-8")
        samples = folder / "samples.txt"
        settings = {"ini": str(ini), "hal": [str(folder / HAL_NAME), str(folder / "sample.hal")],
                    "program": str(program), "samples": str(samples), "fifo": str(fifo / "rtapi_fifo"),
                    "timeout": float(timeout), "dir": str(folder)}
        with open(LOCK_FILE, "a") as lock:
            fcntl.flock(lock, fcntl.LOCK_EX)
            try:
                run = subprocess.run([SYSTEM_PYTHON, str(driver), json.dumps(settings)], cwd=folder,
                                     capture_output=True, text=True, timeout=timeout + 120.0)
            except subprocess.TimeoutExpired:
                raise UserError(f"LinuxCNC did not finish the program within {timeout + 120:.0f} s", source) from None
            finally:
                fcntl.flock(lock, fcntl.LOCK_UN)
        report = _last_json(run.stdout)
        if report is None:
            tail = (run.stderr.strip().splitlines() or ["no output"])[-1]
            raise UserError(f"the LinuxCNC driver failed (exit {run.returncode}): {tail}", source)
        if not report.get("ok"):
            log = (folder / "driver.log").read_text(encoding="utf-8", errors="replace") if (
                folder / "driver.log").exists() else ""
            keep = os.environ.get("VERNE_POST_LINUXCNC_KEEP")
            if keep:
                shutil.copytree(folder, keep, dirs_exist_ok=True)
            said = [x.strip() for x in log.splitlines() if x.strip() and not x.startswith("$ ")]
            tail = f" ({said[-1]})" if said else ""
            raise UserError(f"LinuxCNC: {report.get('error', 'failed')}{tail}", source)
        data = _read_samples(samples)
    return _result(data, tuple(report.get("errors", ())))


def _last_json(stdout: str) -> dict | None:
    for line in reversed(stdout.splitlines()):
        if line.startswith("{"):
            try:
                return json.loads(line)
            except json.JSONDecodeError:
                return None
    return None


def _read_samples(path: Path) -> np.ndarray:
    rows = []
    with open(path, encoding="utf-8", errors="replace") as handle:
        for line in handle:
            parts = line.split()
            if len(parts) == 7:
                try:
                    rows.append([float(p) for p in parts])
                except ValueError:
                    continue
    if not rows:
        raise UserError("LinuxCNC recorded no servo samples")
    return np.asarray(rows)


def _result(data: np.ndarray, errors: tuple[str, ...]) -> SimulationResult:
    index = data[:, 0]
    if np.any(np.diff(index) != 1):
        gaps = int(np.sum(np.diff(index) != 1))
        raise UserError(f"LinuxCNC's sampler lost samples ({gaps} gaps): run with a smaller time scale")
    joints = data[:, 1:6].copy()
    line = data[:, 6].astype(np.int64)
    moving = np.flatnonzero(np.any(np.abs(np.diff(joints, axis=0)) > 0.0, axis=1))
    if len(moving) == 0:
        first, last = 0, 0
    else:
        first, last = int(moving[0]), int(moving[-1]) + 1
    running = np.flatnonzero(line > 0)
    start = min(first, int(running[0]) - 1) if len(running) else first
    start = max(start, 0)
    end = max(last, int(running[-1]) if len(running) else last)
    period = SERVO_PERIOD_NS * 1e-9
    joints = joints[start:end + 1]
    joints[:, 3:] = np.radians(joints[:, 3:])
    t = (np.arange(len(joints)) - (first - start)) * period
    return SimulationResult(t=t, joints=joints, cycle_time=(last - first) * period, line=line[start:end + 1],
                            errors=errors)


_SAMPLER_HAL = """\
# verne-post simulate: every servo period's commanded joints and program line, for halsampler.
loadrt sampler depth=20000 cfg=fffffs
addf sampler.0 servo-thread
setp sampler.0.enable 0
net s-j0 joint.0.pos-cmd => sampler.0.pin.0
net s-j1 joint.1.pos-cmd => sampler.0.pin.1
net s-j2 joint.2.pos-cmd => sampler.0.pin.2
net s-j3 joint.3.pos-cmd => sampler.0.pin.3
net s-j4 joint.4.pos-cmd => sampler.0.pin.4
net s-line motion.program-line => sampler.0.pin.5
"""

# Run with the system Python (the linuxcnc module). Prints one JSON line: {"ok": ..., "errors": [...]}.
_DRIVER = r'''
import ctypes, json, os, pwd, signal, subprocess, sys, time

S = json.loads(sys.argv[1])
LIBC = ctypes.CDLL(None, use_errno=True)
LIBC.prctl(36, 1, 0, 0, 0)  # PR_SET_CHILD_SUBREAPER: every orphan of LinuxCNC becomes ours
NAMESPACED = LIBC.unshare(0x08000000) == 0  # CLONE_NEWIPC: shared memory and semaphores of our own
ME = os.getpid()
NML = "/usr/share/linuxcnc/linuxcnc.nml"
# HAL_KEY, RTAPI_KEY, UUID_KEY; motmod's shared memory (DEFAULT_SHMEM_KEY 100, src/emc/motion/emcmotcfg.h)
HAL_KEYS = (0x48414C32, 0x90280A48, 0x48484C34, 100)
env = dict(os.environ)
env.update(INI_FILE_NAME=S["ini"], NMLFILE=NML, HAL_RTMOD_DIR="/usr/lib/linuxcnc/modules",
           RTAPI_FIFO_PATH=S["fifo"], TRAJ_COORDINATES="", KINS_KINEMATICS="trivkins")
if os.geteuid() == 0:
    env["RTAPI_UID"] = str(pwd.getpwnam("nobody").pw_uid)
os.environ.update(env)
LOG = open(os.path.join(S["dir"], "driver.log"), "a")
ERRORS = []


def run(*args, wait=True):
    LOG.write("$ " + " ".join(args) + "\n"); LOG.flush()
    p = subprocess.Popen(list(args), env=env, cwd=S["dir"], stdout=LOG, stderr=LOG, stdin=subprocess.DEVNULL)
    if wait:
        if p.wait(timeout=60) != 0:
            raise RuntimeError(" ".join(args[:3]) + " failed (exit %d)" % p.returncode)
    return p


def descendants():
    children = {}
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                with open("/proc/%s/stat" % entry) as f:
                    fields = f.read().rsplit(")", 1)[1].split()
            except OSError:
                continue
            if fields[0] != "Z":
                children.setdefault(int(fields[1]), []).append(int(entry))
    out, todo = [], [ME]
    while todo:
        for child in children.get(todo.pop(), []):
            out.append(child); todo.append(child)
    return out


def reap():
    while True:
        try:
            pid, _ = os.waitpid(-1, os.WNOHANG)
        except ChildProcessError:
            return
        if pid == 0:
            return


def stop_all(sampler):
    if sampler is not None and sampler.poll() is None:
        sampler.send_signal(signal.SIGTERM)
        try:
            sampler.wait(timeout=10)
        except subprocess.TimeoutExpired:
            sampler.kill()
    for args in (("halcmd", "stop"), ("halcmd", "unload", "all")):
        try:
            run(*args)
        except Exception as error:
            LOG.write("%s\n" % error)
    for pid in descendants():
        try:
            with open("/proc/%d/comm" % pid) as f:
                comm = f.read().strip()
        except OSError:
            continue
        if comm != "rtapi_app":
            try: os.kill(pid, signal.SIGTERM)
            except ProcessLookupError: pass
    deadline = time.time() + 10
    while descendants() and time.time() < deadline:
        reap()
        if [p for p in descendants() if open("/proc/%d/comm" % p).read().strip() != "rtapi_app"] == []:
            break
        time.sleep(0.05)
    try:
        run("rtapi_app", "exit")
    except Exception as error:
        LOG.write("%s\n" % error)
    deadline = time.time() + 10
    while descendants() and time.time() < deadline:
        reap(); time.sleep(0.05)
    for pid in descendants():
        try: os.kill(pid, signal.SIGKILL)
        except ProcessLookupError: pass
    time.sleep(0.1); reap()
    if not NAMESPACED:
        keys = list(HAL_KEYS)
        for line in open(NML):
            f = line.split()
            if len(f) > 9 and f[0] == "B" and f[2] == "SHMEM":
                keys.append(int(f[9]))
        for key in keys:
            shm = LIBC.shmget(ctypes.c_int(key), 0, 0)
            if shm >= 0:
                LIBC.shmctl(shm, 0, None)  # IPC_RMID
            sem = LIBC.semget(ctypes.c_int(key), 0, 0)
            if sem >= 0:
                LIBC.semctl(sem, 0, 0)  # IPC_RMID


def main():
    sampler = None
    try:
        run("linuxcncsvr", "-ini", S["ini"])
        run("halcmd", "loadusr", "-Wn", "iocontrol", "io", "-ini", S["ini"])
        run("halcmd", "loadrt", "tpmod")
        run("halcmd", "loadrt", "homemod")
        for hal in S["hal"]:
            run("halcmd", "-i", S["ini"], "-f", hal)
        task = run("halcmd", "loadusr", "-Wn", "inihal", "milltask", "-ini", S["ini"], wait=False)
        run("halcmd", "start")
        if task.wait(timeout=60) != 0:
            raise RuntimeError("milltask did not start")
        sampler = subprocess.Popen(["halsampler", "-t"], env=env, cwd=S["dir"], stdin=subprocess.DEVNULL,
                                   stdout=open(S["samples"], "w"), stderr=LOG)
        import linuxcnc
        stat, command, errors = linuxcnc.stat(), linuxcnc.command(), linuxcnc.error_channel()

        def collect():
            while True:
                e = errors.poll()
                if not e:
                    return
                kind = "error" if e[0] in (linuxcnc.NML_ERROR, linuxcnc.OPERATOR_ERROR) else "message"
                ERRORS.append([kind, str(e[1]).strip()])

        def until(what, condition, limit=30.0):
            deadline = time.time() + limit
            while True:
                stat.poll(); collect()
                if condition():
                    return
                if time.time() > deadline:
                    raise RuntimeError("timed out waiting for " + what +
                                       ("; " + ERRORS[-1][1] if ERRORS else ""))
                time.sleep(0.01)

        until("the task", lambda: True)
        command.state(linuxcnc.STATE_ESTOP_RESET); command.wait_complete()
        command.state(linuxcnc.STATE_ON); command.wait_complete()
        until("machine on", lambda: stat.task_state == linuxcnc.STATE_ON)
        command.mode(linuxcnc.MODE_MANUAL); command.wait_complete()
        command.teleop_enable(0); command.wait_complete()
        command.home(-1); command.wait_complete()
        until("homing", lambda: all(stat.homed[k] for k in range(5)))
        command.mode(linuxcnc.MODE_AUTO); command.wait_complete()
        until("auto mode", lambda: stat.task_mode == linuxcnc.MODE_AUTO)
        command.program_open(S["program"]); command.wait_complete()
        run("halcmd", "setp", "sampler.0.enable", "1")
        command.auto(linuxcnc.AUTO_RUN, 0)
        until("the program to start", lambda: stat.interp_state != linuxcnc.INTERP_IDLE, 30.0)
        until("the end of the program", lambda: stat.interp_state == linuxcnc.INTERP_IDLE, S["timeout"])
        until("the motion to settle", lambda: stat.inpos and stat.queue == 0, 30.0)
        time.sleep(0.2)
        collect()
        failed = [text for kind, text in ERRORS if kind == "error"]
        result = {"ok": not failed, "error": "; ".join(failed), "errors": [text for _, text in ERRORS],
                  "namespaced": NAMESPACED}
    except Exception as error:
        result = {"ok": False, "error": str(error).replace("\n", " "), "errors": [t for _, t in ERRORS],
                  "namespaced": NAMESPACED}
    finally:
        try:
            stop_all(sampler)
        except Exception as error:
            LOG.write("cleanup: %s\n" % error)
    print(json.dumps(result)); sys.stdout.flush()


main()
'''


def header_cycle_time(text: str) -> float | None:
    """The planned cycle time (s) of the header's ``(CYCLE TIME ... S`` line; None without one."""
    return _header_cycle_time(text)

"""Due dates, late policies and extensions of the class's assignments, and which submission
of each student ``./course.sh class collect`` takes.

One course configuration file, ``course/course.toml`` in the hub's folder::

    timezone = "Europe/Berlin"          # due dates written without an offset are in this zone

    [assignments.03_observation]
    due = 2027-02-01T23:59:00
    late = "penalty"                    # "none" (the default), "penalty" or "grace"
    penalty_per_day = 0.10              # "penalty": share of the points lost per started day
    grace_hours = 0                     # "grace": hours after the due time still on time

    [assignments.03_observation.extensions]
    alice = 2027-02-04T23:59:00         # alice's own due time

The rules (:func:`choose`), for each student with at least one submission:

- ``none``: the last submission at or before their due time; later ones are not taken;
- ``grace``: the last submission at or before their due time plus ``grace_hours``, in full;
- ``penalty``: their last submission; if it is late, each started day past their due time
  costs ``penalty_per_day`` of its points (never below zero).

When a submission was made is when its files last changed on the hub's disk (the largest
``ctime`` in its folder), not the time its folder's name claims: the student writes that
name, and can change it and the files after the deadline; a ``ctime`` no user can set back.
"""
from __future__ import annotations

import dataclasses
import datetime as dt
import math
import os
import tomllib
from collections.abc import Mapping
from pathlib import Path
from zoneinfo import ZoneInfo, ZoneInfoNotFoundError

__all__ = ["Policy", "Submission", "Choice", "load", "choose", "latest", "inbound", "due_text",
           "LATE_RULES", "CONFIG_NAME"]

#: The course configuration file's name, in the hub's course folder.
CONFIG_NAME = "course.toml"
#: The late policies an assignment may have.
LATE_RULES = ("none", "penalty", "grace")
_KEYS = {"due", "late", "penalty_per_day", "grace_hours", "extensions"}


class DeadlineError(ValueError):
    """A course configuration that cannot be used, saying where and why."""


@dataclasses.dataclass(frozen=True)
class Policy:
    """An assignment's due time (timezone-aware), late rule and per-student extensions."""
    assignment: str
    due: dt.datetime
    late: str = "none"
    penalty_per_day: float = 0.0
    grace: dt.timedelta = dt.timedelta(0)
    extensions: Mapping[str, dt.datetime] = dataclasses.field(default_factory=dict)

    def due_for(self, student: str) -> dt.datetime:
        """The student's due time: their extension, else the assignment's."""
        return self.extensions.get(student, self.due)


@dataclasses.dataclass(frozen=True)
class Submission:
    """One submission in the exchange: whose, when its files last changed (UTC), its folder,
    and the time its name claims (None when it claims none that can be read)."""
    student: str
    at: dt.datetime
    folder: Path | None = None
    claimed: dt.datetime | None = None


@dataclasses.dataclass(frozen=True)
class Choice:
    """What is taken of one student's submissions: the submission (None: none counts), the
    started days it is late, the share of its points kept, and the reason in words."""
    student: str
    submission: Submission | None
    days_late: int
    factor: float
    why: str


def _when(value, zone: ZoneInfo | None, where: str) -> dt.datetime:
    if isinstance(value, dt.datetime):
        if value.tzinfo is None:
            if zone is None:
                raise DeadlineError(f"{where}: {value} has no time zone: write it with an "
                                    "offset (2027-02-01T23:59:00+01:00) or set timezone = "
                                    "\"Europe/Berlin\" (your zone) at the top of the file")
            value = value.replace(tzinfo=zone)
        return value
    raise DeadlineError(f"{where}: {value!r} is not a date and time (write 2027-02-01T23:59:00)")


def load(path) -> dict[str, Policy]:
    """The policies of a course configuration file (module docstring), by assignment; {}
    when the file does not exist. Raises DeadlineError naming the entry for anything it
    cannot use (an unknown key or rule, a time without a zone, a penalty outside 0-1)."""
    path = Path(path)
    if not path.exists():
        return {}
    try:
        conf = tomllib.loads(path.read_text())
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as e:
        raise DeadlineError(f"cannot read {path}: {e}") from None
    unknown = set(conf) - {"timezone", "assignments"}
    if unknown:
        raise DeadlineError(f"{path}: unknown setting(s) {sorted(unknown)}: the file holds "
                            "'timezone' and [assignments.NAME] tables")
    zone = None
    if "timezone" in conf:
        try:
            zone = ZoneInfo(str(conf["timezone"]))
        except (ZoneInfoNotFoundError, ValueError):
            raise DeadlineError(f"{path}: unknown timezone {conf['timezone']!r} (an IANA "
                                "name such as 'Europe/Berlin' or 'America/Chicago')") from None
    policies = {}
    for name, a in (conf.get("assignments") or {}).items():
        where = f"{path} [assignments.{name}]"
        if not isinstance(a, dict):
            raise DeadlineError(f"{where}: must be a table")
        if set(a) - _KEYS:
            raise DeadlineError(f"{where}: unknown key(s) {sorted(set(a) - _KEYS)}; allowed "
                                f"{sorted(_KEYS)}")
        if "due" not in a:
            raise DeadlineError(f"{where}: 'due' is missing")
        late = a.get("late", "none")
        if late not in LATE_RULES:
            raise DeadlineError(f"{where}: late = {late!r}; one of {', '.join(LATE_RULES)}")
        penalty = a.get("penalty_per_day", 0.0)
        if (not isinstance(penalty, (int, float)) or isinstance(penalty, bool)
                or not 0.0 <= penalty <= 1.0):
            raise DeadlineError(f"{where}: penalty_per_day = {penalty!r}; a share from 0 to 1")
        if late == "penalty" and penalty == 0.0:
            raise DeadlineError(f"{where}: late = 'penalty' needs penalty_per_day > 0")
        grace = a.get("grace_hours", 0)
        if (not isinstance(grace, (int, float)) or isinstance(grace, bool)
                or not 0 <= grace <= 24 * 365):
            raise DeadlineError(f"{where}: grace_hours = {grace!r}; hours from 0 up")
        ext = a.get("extensions", {})
        if not isinstance(ext, dict):
            raise DeadlineError(f"{where}: extensions must be a table of student = date")
        due = _when(a["due"], zone, f"{where} due")
        extensions = {str(s): _when(t, zone, f"{where} extensions.{s}") for s, t in ext.items()}
        policies[name] = Policy(name, due, late, float(penalty), dt.timedelta(hours=grace),
                                extensions)
    return policies


def choose(policy: Policy, submissions) -> list[Choice]:
    """For each student among ``submissions`` (:class:`Submission`), the one that counts and
    its share of points under ``policy`` (module docstring), in the students' order."""
    out = []
    for student, subs in _by_student(submissions).items():
        due = policy.due_for(student)
        limit = due + policy.grace if policy.late == "grace" else due
        whose = "their extended" if student in policy.extensions else "the"
        if policy.late == "penalty":
            last = subs[-1]
            days = max(0, math.ceil((last.at - due) / dt.timedelta(days=1)))
            factor = max(0.0, 1.0 - policy.penalty_per_day * days)
            why = (f"last of {len(subs)}, on time" if days == 0 else
                   f"last of {len(subs)}, {days} started day(s) after {whose} due time: "
                   f"{100 * factor:.0f} % of its points")
            out.append(Choice(student, last, days, factor, why))
            continue
        on_time = [s for s in subs if s.at <= limit]
        ignored = len(subs) - len(on_time)
        after = f"; {ignored} later one(s) not taken" if ignored else ""
        if on_time:
            out.append(Choice(student, on_time[-1], 0, 1.0,
                              f"last of {len(on_time)} on time{after}"))
        else:
            out.append(Choice(student, None, 0, 0.0,
                              f"none before {whose} due time"
                              f"{' and grace' if policy.late == 'grace' else ''}"
                              f"{after}"))
    return out


def latest(submissions) -> list[Choice]:
    """Without a due date: each student's last submission, in full."""
    return [Choice(st, subs[-1], 0, 1.0, f"last of {len(subs)}")
            for st, subs in _by_student(submissions).items()]


def _by_student(submissions) -> dict[str, list[Submission]]:
    """Each student's submissions in time order, students in name order; a time without
    its zone is refused."""
    by: dict[str, list[Submission]] = {}
    for s in submissions:
        if s.at.tzinfo is None:
            raise ValueError(f"submission of {s.student}: its time must carry its zone")
        by.setdefault(s.student, []).append(s)
    return {st: sorted(by[st], key=lambda s: s.at) for st in sorted(by)}


def _claimed(name: str) -> dt.datetime | None:
    """The time an exchange folder's name claims (nbgrader's 'YYYY-MM-DD HH:MM:SS.ffffff
    UTC'), or None."""
    parts = name.rsplit("+", 2)
    if len(parts) < 3:
        return None
    text = parts[-2].removesuffix(" UTC")
    for fmt in ("%Y-%m-%d %H:%M:%S.%f", "%Y-%m-%d %H:%M:%S"):
        try:
            return dt.datetime.strptime(text, fmt).replace(tzinfo=dt.timezone.utc)
        except ValueError:
            continue
    return None


def changed_at(folder: Path) -> dt.datetime:
    """The latest ``ctime`` of ``folder`` and everything in it (links not followed), UTC."""
    latest = os.lstat(folder).st_ctime
    for root, dirs, files in os.walk(folder):
        for name in dirs + files:
            latest = max(latest, os.lstat(os.path.join(root, name)).st_ctime)
    return dt.datetime.fromtimestamp(latest, dt.timezone.utc)


def inbound(folder: Path, assignment: str) -> list[Submission]:
    """Every submission of ``assignment`` in an nbgrader inbound folder (entries named
    ``student+assignment+time+random``), timed by :func:`changed_at`."""
    folder = Path(folder)
    subs = []
    for entry in sorted(folder.glob(f"*+{assignment}+*")) if folder.is_dir() else []:
        student, name_assignment = entry.name.split("+", 2)[:2]
        if name_assignment != assignment:
            continue
        subs.append(Submission(student, changed_at(entry), entry, _claimed(entry.name)))
    return subs


def due_text(policy: Policy, student: str | None = None) -> str:
    """The due time and late rule in words, for the chapter's first cell (Markdown)."""
    due = policy.due_for(student) if student else policy.due
    when = due.strftime("%A %d %B %Y, %H:%M") + f" ({due.tzname() or due.strftime('%z')})"
    rule = {"none": "your last submission before then is graded; later ones are not",
            "grace": f"your last submission up to {policy.grace / dt.timedelta(hours=1):g} "
                     "hours after then is graded in full; later ones are not",
            "penalty": "your last submission is graded; if it is late, it loses "
                       f"{100 * policy.penalty_per_day:g} % of its points per started day"
            }[policy.late]
    return f"**Due {when}.** {rule[0].upper()}{rule[1:]}. Submit from the Assignments panel."

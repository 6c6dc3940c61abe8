"""The grader's verdicts and the forms they are written in.

A :class:`Report` (one submission) holds a :class:`CheckResult` per check,
with the check's points; the forms are the text a student reads
(:meth:`Report.text`), one JSON document (:meth:`Report.as_dict`), one CSV
row per submission (:data:`CSV_COLUMNS`, :func:`csv_row`) and Gradescope's
``results.json`` (:func:`gradescope`, the format of Gradescope's autograder
specification, https://gradescope-autograders.readthedocs.io/en/latest/specs/).

Everything here is built by the grader from its own verdicts; the only
text that comes from the student's process (an exception's message) is
reduced to one line of printable characters before it gets here.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from pathlib import Path

#: the columns of ``avblocks lab check N DIR --csv``, in order
CSV_COLUMNS = ("file", "lab", "passed", "points", "max_points", "checks_passed",
               "checks_total", "seed", "failed")

#: what each CSV column holds (``--csv``'s help and docs/labs/index.md)
CSV_HELP = {
    "file": "the submission's file name",
    "lab": "the lab's number",
    "passed": "yes when every check passed, else no",
    "points": "the points earned",
    "max_points": "the points the lab's checks are worth",
    "checks_passed": "how many checks passed",
    "checks_total": "how many checks the lab has",
    "seed": "the seed of the submission's cases (empty: the fixed cases)",
    "failed": "each failed check and its message, separated by ';'",
}

#: Gradescope's visibility values (the specification's "Controlling Test Case Visibility")
VISIBILITY = ("visible", "hidden", "after_due_date", "after_published")

#: what a spreadsheet reads as the start of a formula in a cell (OWASP, "CSV Injection")
_FORMULA = ("=", "+", "-", "@", "\t", "\r")


def no_surrogates(text) -> str:
    """``text`` with each byte that was not UTF-8 in a file name (Python's
    ``surrogateescape``: U+DC80 to U+DCFF) written as ``\\xNN``, so that it
    can be printed and encoded (a strict UTF-8 stdout raised on it)."""
    text = str(text)
    if not any("\udc80" <= c <= "\udcff" for c in text):
        return text.encode("utf-8", "replace").decode("utf-8")
    return "".join(f"\\x{ord(c) - 0xDC00:02x}" if "\udc80" <= c <= "\udcff" else c
                   for c in text).encode("utf-8", "replace").decode("utf-8")


def shown(text) -> str:
    """``text`` (a file name: the student's) as one line of printable text:
    undecodable bytes as ``\\xNN``, other control characters (newlines,
    terminal escapes) as ``?``."""
    return "".join(c if c.isprintable() else "?" for c in no_surrogates(text))


def csv_cell(text) -> str:
    """``text`` made safe for a CSV cell that a spreadsheet opens: printable
    (:func:`shown`), and a leading ``=``, ``+``, ``-`` or ``@`` (a formula:
    ``=HYPERLINK(...)``, ``=cmd|...``) escaped by a ``'`` before it."""
    text = shown(text)
    return "'" + text if text.startswith(_FORMULA) else text


@dataclass
class CheckResult:
    """One check of one submission.

    Attributes
    ----------
    name : str
    passed : bool
    message : str
        What the check found (its note when it passed, the reason when not).
    points : float
        What the check is worth; 0 for the grader's own entries (``load``:
        the file did not load; ``files``: it changed files it must not).
    visibility : str
        Gradescope's visibility of the check (one of :data:`VISIBILITY`).
    """

    name: str
    passed: bool
    message: str = ""
    points: float = 1.0
    visibility: str = "visible"

    @property
    def score(self) -> float:
        """The points earned: all of them when passed, none otherwise."""
        return float(self.points) if self.passed else 0.0


@dataclass
class Report:
    """Every check of one submission.

    Attributes
    ----------
    lab : int
    file : str
    checks : list of CheckResult
    seed : int or None
        The seed its cases were drawn with (None: the fixed cases).
    limits : dict
        What the grader set for the student's process (``{limit: in words}``),
        as the platform allowed.
    """

    lab: int
    file: str
    checks: list[CheckResult] = field(default_factory=list)
    seed: int | None = None
    limits: dict = field(default_factory=dict)

    @property
    def passed(self) -> bool:
        return bool(self.checks) and all(c.passed for c in self.checks)

    @property
    def graded(self) -> list:
        """The lab's checks (not the grader's own ``load``/``files`` entries)."""
        return [c for c in self.checks if c.points > 0]

    @property
    def score(self) -> tuple[int, int]:
        """``(checks passed, checks of the lab)``: a file that did not load
        scores 0 of every check, not 0 of 1."""
        g = self.graded
        return sum(c.passed for c in g), len(g)

    @property
    def points(self) -> tuple[float, float]:
        """``(points earned, points possible)``."""
        g = self.graded
        return (sum(c.score for c in g) if self.passed_entries() else 0.0,
                float(sum(c.points for c in g)))

    def passed_entries(self) -> bool:
        """False when a grader's entry (``files``) voids the submission."""
        return all(c.passed for c in self.checks if c.name == "files")

    def as_dict(self) -> dict:
        ok, total = self.score
        got, most = self.points
        return {"lab": self.lab, "file": no_surrogates(self.file), "passed": self.passed,
                "checks_passed": ok, "checks_total": total, "points": got,
                "max_points": most, "seed": self.seed, "limits": dict(self.limits),
                "checks": [asdict(c) for c in self.checks]}

    def text(self) -> str:
        ok, total = self.score
        got, most = self.points
        lines = [f"lab {self.lab}: {shown(self.file)}"
                 + (f" (cases of seed {self.seed})" if self.seed is not None else "")]
        skipped = [c for c in self.checks if c.message.startswith("not run: the file did "
                                                                    "not load")]
        for c in self.checks:
            if c in skipped:
                continue
            mark = "PASS" if c.passed else "FAIL"
            msg = c.message.replace("\n", "\n        ")
            lines.append(f"  {mark}  {c.name}" + (f": {msg}" if msg else ""))
        if skipped:
            lines.append(f"  (the lab's {len(skipped)} checks were not run)")
        pts = "" if most == total else f", {got:g} of {most:g} points"
        lines.append(f"{ok} of {total} checks passed{pts}" + (
            "" if self.passed else "; see the FAIL lines above"))
        return "\n".join(lines)


def csv_row(r: Report) -> list:
    """The CSV row of one submission (columns :data:`CSV_COLUMNS`); the
    texts through :func:`csv_cell` (a file's name is the student's)."""
    ok, total = r.score
    got, most = r.points
    return [csv_cell(Path(r.file).name), r.lab, "yes" if r.passed else "no", f"{got:g}",
            f"{most:g}", ok, total, "" if r.seed is None else r.seed,
            csv_cell("; ".join(f"{c.name}: {c.message}" for c in r.checks
                               if not c.passed and not c.message.startswith("not run: the "
                                                                            "file")))]


def gradescope(r: Report, *, execution_time=None) -> dict:
    """Gradescope's ``results.json`` for one submission: one test per check
    (name, score, max_score, status, output, visibility) and the total
    score. The grader's own entries (``load``, ``files``) become the
    top-level ``output`` (shown to the student), worth no points."""
    tests = []
    for i, c in enumerate(r.graded, 1):
        tests.append({"name": c.name, "number": f"{r.lab}.{i}", "score": c.score,
                      "max_score": float(c.points), "status": "passed" if c.passed else "failed",
                      "output": c.message, "output_format": "text",
                      "visibility": c.visibility if c.visibility in VISIBILITY else "visible"})
    got, most = r.points
    notes = [f"{c.name}: {c.message}" for c in r.checks if c.points == 0 and not c.passed]
    # the summary a student sees at once counts the visible checks only: the
    # others' results show when their visibility says so
    seen = [c for c in r.graded if c.visibility == "visible"]
    ok, total = sum(c.passed for c in seen), len(seen)
    pts, most_seen = sum(c.score for c in seen), sum(c.points for c in seen)
    head = f"lab {r.lab}: {ok} of {total} checks passed, {pts:g} of {most_seen:g} points"
    later = len(r.graded) - len(seen)
    if later:
        head += f" (and {later} more check{'s' if later > 1 else ''} shown later)"
    if r.seed is not None:
        head += f" (cases of seed {r.seed})"
    doc = {"score": float(got), "output": "\n".join([head] + notes), "output_format": "text",
           "test_output_format": "text", "test_name_format": "text",
           "stdout_visibility": "hidden", "tests": tests}
    if execution_time is not None:
        doc["execution_time"] = max(0, int(round(execution_time)))
    return doc

"""Did the test suite really run? Reads pytest's own JUnit XML report and fails (exit status 1, one
line per problem) unless:

* the report exists and parses (a run that ended early, e.g. a process that exited in the middle of
  the suite, writes none);
* it counts at least one test, and as many as were collected (tests/conftest.py writes the number
  collected into the report as the suite property ``collected``; fewer reported means the run
  stopped early, e.g. -x or an interruption);
* every test passed, or was skipped for a reason the README lists: the backquoted items of the list
  that follows the line containing ``SKIP_REASONS_MARKER`` (a skip message passes if it contains one).

Usage: python .ci/check_report.py REPORT.xml README.md   (standard library only)
"""
import re
import sys
import xml.etree.ElementTree as ET

SKIP_REASONS_MARKER = "skipped only for these reasons"


def allowed_skip_reasons(readme_text: str) -> list[str]:
    """The backquoted reasons of the bullet list after the README line with SKIP_REASONS_MARKER."""
    lines = readme_text.splitlines()
    for i, line in enumerate(lines):
        if SKIP_REASONS_MARKER in line:
            reasons = []
            for item in lines[i + 1:]:
                if not item.strip():
                    if reasons:
                        break
                    continue
                if not item.lstrip().startswith(("-", "*")):
                    break
                reasons.extend(re.findall(r"`([^`]+)`", item))
            return reasons
    return []


def problems(report_path: str, readme_path: str) -> list[str]:
    """Every reason the report at ``report_path`` does not show a complete, green run (empty: it does)."""
    try:
        root = ET.parse(report_path).getroot()
    except (OSError, ET.ParseError) as exc:
        return [f"no readable test report ({exc}): the suite did not finish"]
    with open(readme_path, encoding="utf-8") as fh:
        allowed = allowed_skip_reasons(fh.read())
    suites = [root] if root.tag == "testsuite" else root.findall("testsuite")
    out = []
    collected = [p.get("value") for s in suites for p in s.iter("property") if p.get("name") == "collected"]
    cases = {}
    for s in suites:
        for case in s.iter("testcase"):
            cases.setdefault((case.get("classname"), case.get("name")), []).append(case)
    if not cases:
        out.append("no test ran (0 tests in the report)")
    if not collected:
        out.append("the report does not say how many tests were collected (tests/conftest.py's "
                   "suite property 'collected' is missing: did the suite's conftest run?)")
    elif int(collected[0]) != len(cases):
        out.append(f"{collected[0]} tests were collected but {len(cases)} reported: the run ended early")
    for (cls, name), entries in sorted(cases.items(), key=lambda kv: (kv[0][0] or "", kv[0][1] or "")):
        for case in entries:
            for tag in ("failure", "error"):
                for el in case.findall(tag):
                    out.append(f"{cls}::{name}: {tag}: {(el.get('message') or '').splitlines()[0:1]}")
            for el in case.findall("skipped"):
                msg = (el.get("message") or "") + " " + (el.text or "")
                if not any(reason in msg for reason in allowed):
                    out.append(f"{cls}::{name}: skipped for a reason the README does not list: "
                               f"{(el.get('message') or '').strip()!r}")
    return out


def main(argv) -> int:
    if len(argv) != 3:
        print(__doc__.strip().splitlines()[-1], file=sys.stderr)
        return 2
    found = problems(argv[1], argv[2])
    for line in found:
        print(f"ci: {line}", file=sys.stderr)
    if not found:
        print(f"ci: the report holds every collected test, all passed or skipped for listed reasons")
    return 1 if found else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))

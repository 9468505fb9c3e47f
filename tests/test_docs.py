"""The README and docs/ as users read them: every relative link and picture exists, the README's
Python examples run as pasted (in the pip `bpy` module, in order, each in a fresh namespace), the
user's pages carry no issue numbers, dates or days, the README stays a page (its picture first,
at most about 15k characters), and the manual names every setting and operator (the README's
table of names only names that exist)."""
import contextlib
import io
import re
from pathlib import Path

import pytest

import bpy  # noqa: E402

from blender_session import empty_file, registered  # noqa: E402,F401  (autouse fixtures)

ROOT = Path(__file__).resolve().parent.parent
README = ROOT / "README.md"
PAGES = [README] + sorted((ROOT / "docs").glob("*.md"))
USER_PAGES = [p for p in PAGES if p.name not in ("ARCHITECTURE.md", "development.md")]
LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)\)")


def _targets(page: Path):
    """The relative targets of the page's markdown links and pictures (anchors dropped)."""
    text = re.sub(r"```.*?```", "", page.read_text(encoding="utf-8"), flags=re.S)
    for m in LINK.finditer(text):
        target = m.group(1)
        if re.match(r"[a-z]+:", target) or target.startswith("#"):
            continue
        yield target.split("#", 1)[0]


@pytest.mark.parametrize("page", PAGES, ids=lambda p: p.name)
def test_relative_links_and_pictures_exist(page):
    targets = list(_targets(page))
    missing = [t for t in targets if not (page.parent / t).exists()]
    assert not missing, f"{page.name}: {missing}"


def test_the_docs_index_lists_every_page():
    index = (ROOT / "docs" / "README.md").read_text()
    listed = set(_targets(ROOT / "docs" / "README.md"))
    pages = {p.name for p in (ROOT / "docs").glob("*.md")} - {"README.md"}
    assert pages <= listed, pages - listed
    assert "manual.md" in index


ISSUE = re.compile(r"\bissues? ?#?\d+|(?<![\w/])#\d+\b", re.I)
DATE = re.compile(r"\b(19|20)\d\d-\d\d-\d\d\b|\b(today|yesterday|tomorrow|monday|tuesday|wednesday|thursday|"
                  r"friday|saturday|sunday)\b|\b(fast|slow|that|one|same|a|the|faster) day\b", re.I)


@pytest.mark.parametrize("page", USER_PAGES, ids=lambda p: p.name)
def test_user_pages_have_no_issue_numbers_dates_or_days(page):
    text = page.read_text(encoding="utf-8")
    found = [m.group(0) for m in ISSUE.finditer(text)] + [m.group(0) for m in DATE.finditer(text)]
    assert not found, f"{page.name}: {found}"


def test_the_readme_is_a_user_s_page():
    text = README.read_text(encoding="utf-8")
    assert len(text) <= 15000, len(text)
    assert re.match(r"# grlens\s+!\[[^\]]+\]\(docs/images/\w+\.png\)", text), "a picture first"
    for must in ("Install from Disk", "bl_ext.user_default.grlens", "4.2 LTS", "4.5 LTS", "5.0",
                 "scripts/build_extension.py", "./dev main", "./dev test", "Add (Shift+A) > **Black Hole**",
                 "docs/manual.md", "docs/README.md"):
        assert must in text, must
    headings = re.findall(r"^## (.+)$", text, flags=re.M)
    assert headings[:3] == ["Install", "Five minutes with grlens", "Scripting"], headings


def _python_blocks():
    return re.findall(r"```python\n(.*?)```", README.read_text(encoding="utf-8"), flags=re.S)


def test_the_readme_s_python_examples_run_as_pasted():
    blocks = _python_blocks()
    assert len(blocks) >= 4
    outputs = []
    for code in blocks:
        out = io.StringIO()
        with contextlib.redirect_stdout(out):
            exec(compile(code, "README.md", "exec"), {"__name__": "__main__"})  # noqa: S102
        outputs.append(out.getvalue())
    scene = bpy.context.scene
    # the first example built a lensed sphere with its hole and camera
    assert re.search(r"1 object\(s\) lensed, r_obs = 20 r_s.*\[\d+ ms\]", outputs[0]), outputs[0]
    assert "Mesh(" in outputs[0] or "Sphere.GR1" in outputs[0]
    # the second lit it with GR illumination
    assert "nothing left out" in outputs[1] or outputs[1].strip(), outputs[1]
    # the third checked a frame against the ray tracer and unlensed everything
    assert "mismatch" in outputs[2] or "%" in outputs[2], outputs[2]
    assert not [o for o in bpy.data.objects if o.grlens.order in (1, 2)]
    assert scene.grlens.black_hole is not None and scene.grlens.black_hole.empty_display_size == 2.0
    assert "0.1269" in outputs[3]


def test_the_manual_names_every_setting_and_operator():
    manual = (ROOT / "docs" / "manual.md").read_text(encoding="utf-8")
    readme = README.read_text(encoding="utf-8")
    scene_props = {p.identifier for p in bpy.context.scene.grlens.bl_rna.properties} - {"rna_type", "name"}
    obj_props = {p.identifier for p in bpy.data.objects.new("x", None).grlens.bl_rna.properties
                 if not p.is_hidden} - {"rna_type", "name"}
    ops = {name for name in dir(bpy.ops.grlens) if not name.startswith("_")}
    assert ops >= {"add_black_hole", "lens_selected", "unlens_selected", "clear", "rebuild"}
    for name in sorted(scene_props | obj_props):
        assert re.search(rf"`[^`]*\b{name}\b[^`]*`", manual), name
    for name in sorted(ops):
        assert f"bpy.ops.grlens.{name}" in manual or f"`{name}()`" in manual, name
    # the README's table of names holds only names that exist
    table = {m.group(1): m.group(2) for m in re.finditer(r"^\| `(scene\.grlens|obj\.grlens|bpy\.ops\.grlens)` \| (.+) \|$",
                                                         readme, flags=re.M)}
    assert set(table) == {"scene.grlens", "obj.grlens", "bpy.ops.grlens"}, table
    for owner, names in (("scene.grlens", scene_props), ("obj.grlens", obj_props | {"source", "order"}),
                         ("bpy.ops.grlens", ops)):
        listed = set(re.findall(r"`(\w+)`", table[owner]))
        assert listed and listed <= names, (owner, listed - names)

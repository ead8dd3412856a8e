"""The documentation holds together: README.md and docs/ link only to files (and headings) inside
the repository, no file refers to a directory beside it, every docs page says its kind, the
index lists every page, every result says how to regenerate it, and the mission-file reference
is the schema's."""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
DOCS = REPO / "docs"
LINK = re.compile(r"\]\(([^)\s]+)\)")
FENCE = re.compile(r"^```.*?^```", re.S | re.M)
KINDS = ("concept", "reference", "guide", "result")
KIND_LINE = re.compile(r"^Kind: (\w+)$", re.M)


def _docs_pages() -> list[Path]:
    return sorted(DOCS.rglob("*.md"))


def _markdown() -> list[Path]:
    return [REPO / "README.md", REPO / "CHANGELOG.md", REPO / "sim" / "README.md",
            REPO / "missions" / "README.md", *_docs_pages()]


def slug(heading: str) -> str:
    """The anchor GitHub gives a heading: lower case, punctuation dropped, spaces as hyphens."""
    text = re.sub(r"[^\w\- ]", "", heading.strip().lower())
    return text.replace(" ", "-")


def anchors(doc: Path) -> set[str]:
    text = FENCE.sub("", doc.read_text(encoding="utf-8"))
    return {slug(m) for m in re.findall(r"^#{1,6} (.+)$", text, flags=re.M)}


def test_slug_is_githubs() -> None:
    assert slug("The full batches (seed 0, 50 starts x 2 repetitions)") == (
        "the-full-batches-seed-0-50-starts-x-2-repetitions")
    assert slug("The bank's radius") == "the-banks-radius"
    assert slug("`mexgen-gcs check MISSION.yaml`") == "mexgen-gcs-check-missionyaml"


def test_links_point_at_files_and_headings_in_the_repository() -> None:
    checked = 0
    for doc in _markdown():
        for target in LINK.findall(FENCE.sub("", doc.read_text(encoding="utf-8"))):
            if target.startswith(("http://", "https://", "mailto:")):
                continue
            file_part, _, anchor = target.partition("#")
            path = (doc.parent / file_part).resolve() if file_part else doc
            assert path.is_relative_to(REPO), f"{doc.name}: {target} is outside the repository"
            assert path.exists(), f"{doc.name}: {target} does not exist"
            if anchor and path.suffix == ".md":
                assert anchor in anchors(path), f"{doc.name}: {target}: no such heading"
            checked += 1
    assert checked >= 50


def test_every_docs_page_says_its_kind_once_on_its_first_line() -> None:
    pages = _docs_pages()
    assert len(pages) >= 14
    for page in pages:
        text = page.read_text(encoding="utf-8")
        kinds = KIND_LINE.findall(text)
        assert len(kinds) == 1, f"{page.relative_to(REPO)}: {len(kinds)} kind lines"
        assert text.startswith(f"Kind: {kinds[0]}\n"), f"{page.relative_to(REPO)}: not first"
        assert kinds[0] in KINDS, f"{page.relative_to(REPO)}: kind {kinds[0]!r}"
        in_results = page.parent == DOCS / "results"
        assert (kinds[0] == "result") == in_results, (
            f"{page.relative_to(REPO)}: results, and only results, live in docs/results/")


def test_the_index_lists_every_page() -> None:
    index = (DOCS / "index.md").read_text(encoding="utf-8")
    listed = {(DOCS / t.partition("#")[0]).resolve() for t in LINK.findall(index)}
    missing = [str(p.relative_to(REPO)) for p in _docs_pages()
               if p.name != "index.md" and p.resolve() not in listed]
    assert missing == []


def test_every_result_says_how_to_regenerate_it_and_on_which_commit() -> None:
    results = sorted((DOCS / "results").glob("*.md"))
    assert len(results) >= 3
    for page in results:
        text = page.read_text(encoding="utf-8")
        assert re.search(r"`(mexgen-gcs|python) [^`]+`", text), f"{page.name}: no command"
        assert re.search(r"\bcommits? [0-9a-f]{7,40}\b", text), f"{page.name}: no commit"


def test_the_mission_file_reference_is_generated_from_the_schema() -> None:
    from mexgen_gcs.config.reference import markdown_reference

    text = (DOCS / "mission-file.md").read_text(encoding="utf-8")
    assert text == markdown_reference(), (
        "docs/mission-file.md is out of date: python -m mexgen_gcs.config.reference > "
        "docs/mission-file.md")
    assert "`radio.p0_std_db`" in text and "`sim.faults[kind=clutter].rate_per_s`" in text


def test_docs_exist_for_every_contract() -> None:
    for name in ("architecture.md", "wire-format.md", "flight-log.md", "truth-file.md",
                 "cli.md", "mission-file.md", "estimator.md", "planner.md", "field-guide.md",
                 "index.md", "schemas/wire-v1.schema.json",
                 "schemas/flight-log-v1.schema.json", "schemas/truth-v1.schema.json"):
        assert (DOCS / name).is_file(), name
    readme = (REPO / "README.md").read_text(encoding="utf-8")
    for name in ("index.md", "architecture.md", "wire-format.md", "flight-log.md",
                 "truth-file.md", "cli.md", "mission-file.md", "field-guide.md"):
        assert f"(docs/{name})" in readme, name
    for name in ("LICENSE", "CITATION.cff", "CHANGELOG.md"):
        assert (REPO / name).is_file(), name


#: files owned by other branches that still point outside; the lead empties this as they merge
KNOWN_ELSEWHERE: frozenset[str] = frozenset()


def test_nothing_refers_outside_the_repository() -> None:
    """No path to the shared directory beside the repository, nor to the workplace, in any
    tracked file of README.md, docs, mexgen_gcs, sim, tests or missions."""
    outside = "." * 2 + "/" + "shared"  # spelled so that this file does not match itself
    workplace = "/" + "work" + "/"
    proc = subprocess.run(["git", "grep", "-n", "-I", "-F", "-e", outside, "-e", workplace,
                           "--", "README.md", "docs", "mexgen_gcs", "sim", "tests", "missions"],
                          cwd=REPO, capture_output=True, text=True, check=False)
    assert proc.returncode in (0, 1), proc.stderr
    hits = proc.stdout.splitlines()
    files = {line.split(":", 1)[0] for line in hits}
    assert files <= KNOWN_ELSEWHERE, [h for h in hits if h.split(":", 1)[0] not in
                                      KNOWN_ELSEWHERE]
    assert files == KNOWN_ELSEWHERE, f"fixed: remove {KNOWN_ELSEWHERE - files} from the list"


def test_only_results_carry_dates_and_commits() -> None:
    """Concepts, reference and guides say what is true now; when and on which commit something
    was measured belongs to docs/results/."""
    pages = [p for p in _markdown() if p.parent != DOCS / "results" and p.name != "CHANGELOG.md"]
    for page in pages:
        text = page.read_text(encoding="utf-8")
        assert not re.search(r"\b20\d\d-\d\d-\d\d\b", text), f"{page.relative_to(REPO)}: a date"
        assert not re.search(r"\bcommits? [0-9a-f]{7,40}\b", text), (
            f"{page.relative_to(REPO)}: a commit")

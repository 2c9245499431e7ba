"""Every citation of the design in the project ("DESIGN section 3", "DESIGN sections 3 and 5", "DESIGN
section 4.4") names a section that docs/DESIGN.md has (a heading "## 3." or "### 4.4"), and nothing points
to a design outside the repository.

Usage: TestDesignCitations.py SOURCE_DIR
"""
import os
import re
import sys

CITATION = re.compile(r"DESIGN(?:\.md)? sections? ((?:\d+(?:\.\d+)?)(?:(?:, | and | or )\d+(?:\.\d+)?)*)")
SUFFIXES = (".h", ".cxx", ".cu", ".py", ".md", ".txt", ".cmake", ".sh", ".xml", ".in")
SKIP = {"build", "build-asan", "build-fuzz", "build-paraview-prefix", ".git"}


def sections(design):
    """The section numbers of the design's headings: "## 3. Title" -> 3, "### 4.4 Title" -> 4.4."""
    found = set()
    for line in open(design, encoding="utf-8"):
        m = re.match(r"#{2,3} (\d+(?:\.\d+)?)\.? ", line)
        if m:
            found.add(m.group(1))
    return found


def main():
    root = sys.argv[1]
    design = os.path.join(root, "docs", "DESIGN.md")
    assert os.path.isfile(design), design
    known = sections(design)
    assert {str(n) for n in range(1, 10)} <= known, sorted(known)
    citations, missing, outside = 0, [], []
    for folder, dirs, files in os.walk(root):
        dirs[:] = [d for d in dirs if d not in SKIP and not d.startswith("build")]
        for name in files:
            if not name.endswith(SUFFIXES) or name == "TestDesignCitations.py":
                continue
            path = os.path.join(folder, name)
            try:
                text = open(path, encoding="utf-8").read()
            except UnicodeDecodeError:
                continue
            for number, line in enumerate(text.splitlines(), 1):
                if "shared/docs/DESIGN" in line:
                    outside.append("%s:%d" % (os.path.relpath(path, root), number))
                for m in CITATION.finditer(line):
                    for section in re.split(r", | and | or ", m.group(1)):
                        citations += 1
                        if section not in known:
                            missing.append("%s:%d cites section %s" % (os.path.relpath(path, root), number, section))
    print("%d citations of docs/DESIGN.md, sections %s" % (citations, ", ".join(sorted(known))))
    assert citations > 30, citations  # the code cites the design throughout; none found means the scan broke
    assert not missing, "citations of sections docs/DESIGN.md does not have:\n" + "\n".join(missing)
    assert not outside, "references to a design outside the repository:\n" + "\n".join(outside)


if __name__ == "__main__":
    main()

"""The documentation in layers: a short top README that leads on, a README per package, design notes
one topic per page in vr_driver/doc/ (each listed in its index), bench figures in bench/README.md; no
issue numbers and no stale words in any of them; every relative link resolves, to a file and, where it
names one, to a heading of that file."""
import os
import re
import unittest

from test_references import LINK, REPO, package_dirs, read, repo_files

#: the top README's budget: what it is, the two commands, a tour, which protocol, where to read on
TOP_README_LINES = 250
#: words that must not come back: an issue number in a heading or the text, and the model's
#: dimensions called placeholders (they are TA-1400-class values to calibrate), a removed command
STALE = [(re.compile(r"\bissue \d+", re.I), "an issue number"),
         (re.compile(r"\(issue\b", re.I), "an issue reference"),
         (re.compile(r"placeholder", re.I), "'placeholder'"),
         # one calibrate command (vr_driver's): the support package's own left out the self-collision check
         (re.compile(r"panasonic_vr006l_support calibrate"), "the support package's removed calibrate command")]


def slug(heading):
    """GitHub's anchor of a Markdown heading: lower case, punctuation dropped but - and _, spaces -> -."""
    text = re.sub(r"`|\*\*", "", heading.strip().lower())
    return re.sub(r"[^\w\- ]", "", text).replace(" ", "-")


def anchors(text):
    found = set()
    fenced = False
    for line in text.splitlines():
        if line.startswith("```"):
            fenced = not fenced
        elif not fenced and line.startswith("#"):
            found.add(slug(line.lstrip("#")))
    return found


class DocsTest(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.docs = [f for f in repo_files() if f.endswith(".md") and os.path.isfile(os.path.join(REPO, f))]

    def test_the_top_readme_is_short(self):
        n = len(read("README.md").splitlines())
        self.assertLessEqual(n, TOP_README_LINES, "README.md has %d lines: move details to a package README, "
                             "vr_driver/doc/ or bench/README.md" % n)

    def test_every_package_has_a_readme(self):
        missing = [p for p in package_dirs() if not os.path.isfile(os.path.join(REPO, p, "README.md"))]
        self.assertEqual(missing, [])
        self.assertGreaterEqual(len(package_dirs()), 4)

    def test_the_top_readme_leads_to_every_package_readme_and_the_doc_index(self):
        text = read("README.md")
        for target in ["%s/README.md" % p for p in package_dirs()] + ["vr_driver/doc/README.md", "bench/README.md"]:
            self.assertIn("](%s" % target, text, "README.md does not link to %s" % target)

    def test_every_design_note_is_in_the_doc_index(self):
        index = read("vr_driver/doc/README.md")
        notes = sorted(f for f in os.listdir(os.path.join(REPO, "vr_driver", "doc"))
                       if f.endswith(".md") and f != "README.md")
        self.assertGreaterEqual(len(notes), 10)
        self.assertEqual([n for n in notes if "](%s)" % n not in index], [], "not listed in vr_driver/doc/README.md")

    def test_no_issue_numbers_nor_stale_words(self):
        bad = ["%s:%d: %s: %s" % (doc, n, what, line.strip())
               for doc in self.docs for n, line in enumerate(read(doc).splitlines(), 1)
               for pattern, what in STALE if pattern.search(line)]
        self.assertEqual(bad, [])

    def test_one_section_per_topic_in_each_document(self):
        bad = []
        for doc in self.docs:
            seen = {}
            for line in read(doc).splitlines():
                if re.match(r"#{1,3} ", line):
                    key = slug(line.lstrip("#"))
                    if key in seen:
                        bad.append("%s: %r twice" % (doc, line.strip()))
                    seen[key] = True
        self.assertEqual(bad, [])

    def test_relative_links_resolve_to_a_file_and_its_heading(self):
        bad = []
        for doc in self.docs:
            text = read(doc)
            for n, line in enumerate(text.splitlines(), 1):
                for target in LINK.findall(line):
                    if re.match(r"[a-z][a-z0-9+.-]*:", target):
                        continue            # http:, mailto:
                    path, _, anchor = target.partition("#")
                    full = os.path.normpath(os.path.join(REPO, os.path.dirname(doc), path)) if path else \
                        os.path.join(REPO, doc)
                    if not full.startswith(REPO + os.sep) or not os.path.exists(full):
                        bad.append("%s:%d: %s (no such file)" % (doc, n, target))
                    elif anchor and full.endswith(".md") and anchor not in anchors(read(os.path.relpath(full, REPO))):
                        bad.append("%s:%d: %s (no such heading)" % (doc, n, target))
        self.assertEqual(bad, [])

    def test_the_reasons_for_our_own_code_are_reachable_from_the_top_readme(self):
        """Prefer a well-kept library; where we wrote our own, the README says why."""
        text = read("README.md")
        self.assertIn("## Why some parts are our own", text)
        self.assertIn("pyprofibus_vendor/README.md#why-our-own-stack", text)
        self.assertIn("## Why our own stack", read("pyprofibus_vendor/README.md"))


if __name__ == "__main__":
    unittest.main()


#: a code comment's pointer to a README section: README "X", README, "X", README.md, "X",
#: README.md, section X (the section name up to the closing quote or parenthesis)
README_POINTER = re.compile(r'README(?:\.md)?,? (?:section )?"([^"]+)"|README(?:\.md)?, section ([^)"]+)\)')
CODE_SUFFIXES = (".py", ".msg", ".srv", ".action", ".launch", ".test", ".yaml", ".srdf", ".xacro", ".rst", ".cfg")


class CodePointersTest(unittest.TestCase):
    def test_a_comment_that_names_a_readme_section_names_one_that_exists(self):
        """Sections move between the READMEs and vr_driver/doc/: a pointer in the code to a heading no
        Markdown file has any more leads nowhere."""
        headings = set()
        for f in repo_files():
            if f.endswith(".md") and os.path.isfile(os.path.join(REPO, f)):
                headings |= {h.replace("-", " ") for h in anchors(read(f))}
        stale = []
        for f in repo_files():
            if not f.endswith(CODE_SUFFIXES) or not os.path.isfile(os.path.join(REPO, f)) or f == "test/test_docs.py":
                continue
            for n, line in enumerate(read(f).splitlines(), 1):
                for m in README_POINTER.finditer(line):
                    name = (m.group(1) or m.group(2)).strip()
                    if slug(name).replace("-", " ") not in headings:
                        stale.append("%s:%d: %s" % (f, n, name))
        self.assertEqual(stale, [], "pointers to README sections that no Markdown file has")

"""Every reference in the documentation resolves inside the repository: relative links and images
of every Markdown file, file paths quoted in backticks, and documents named anywhere (code comments
included). Nothing may point outside the repository (``../shared``)."""
import os
import re
import subprocess
import unittest

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SKIP_DIRS = {".git", ".ws", "__pycache__", ".pytest_cache", ".hypothesis"}
TEXT_EXT = (".md", ".py", ".yaml", ".yml", ".xacro", ".urdf", ".launch", ".test", ".rviz", ".msg", ".action",
            ".srdf", ".xml", ".txt", ".cfg", ".ini", ".toml", ".gsd", "")
LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)(?:\s+\"[^\"]*\")?\)")
# a file path in backticks: at least one slash, ends in an extension of a file kind we ship
QUOTED_PATH = re.compile(r"`([A-Za-z0-9_.\-/]+/[A-Za-z0-9_.\-]+\.(?:md|py|yaml|xacro|launch|rviz|gsd|csr|png|"
                         r"action|msg|test|srdf|toml))`")
# a document named by its file name, e.g. DESIGN.md, controller_program.md
DOC_NAME = re.compile(r"(?<![\w/.-])([A-Za-z][A-Za-z0-9_-]*\.md)\b")


def repo_files():
    """Tracked files (git), or every file below the repository without git."""
    try:
        out = subprocess.run(["git", "ls-files", "-z"], cwd=REPO, capture_output=True, check=True).stdout
        files = [f for f in out.decode().split("\0") if f]
        if files:
            return files
    except (OSError, subprocess.CalledProcessError):
        pass
    found = []
    for top, dirs, names in os.walk(REPO):
        dirs[:] = [d for d in dirs if d not in SKIP_DIRS]
        found += [os.path.relpath(os.path.join(top, n), REPO) for n in names]
    return found


def read(path):
    with open(os.path.join(REPO, path), encoding="utf-8", errors="replace") as f:
        return f.read()


def package_dirs():
    return sorted(d for d in os.listdir(REPO) if os.path.isfile(os.path.join(REPO, d, "package.xml")))


def resolves(target, doc):
    """A quoted path counts as present relative to the document, the repository or a package."""
    bases = [os.path.dirname(os.path.join(REPO, doc)), REPO] + [os.path.join(REPO, p) for p in package_dirs()]
    return any(os.path.exists(os.path.normpath(os.path.join(b, target))) for b in bases)


class ReferencesTest(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.files = [f for f in repo_files() if os.path.isfile(os.path.join(REPO, f))]
        cls.docs = [f for f in cls.files if f.endswith(".md")]
        this = os.path.relpath(os.path.abspath(__file__), REPO)      # names the bad examples itself
        cls.text = [f for f in cls.files if os.path.splitext(f)[1] in TEXT_EXT and f != this
                    and not os.path.islink(os.path.join(REPO, f))]
        cls.basenames = {os.path.basename(f) for f in cls.files}

    def test_the_docs_are_found(self):
        for doc in ("README.md", "vr_driver/doc/README.md", "vr_driver/doc/controller_program.md"):
            self.assertIn(doc, self.docs)

    def test_markdown_links_and_images_exist(self):
        bad = []
        for doc in self.docs:
            for n, line in enumerate(read(doc).splitlines(), 1):
                for target in LINK.findall(line):
                    if re.match(r"[a-z][a-z0-9+.-]*:", target) or target.startswith("#"):
                        continue            # http:, mailto:, an anchor in the same page
                    path = target.split("#", 1)[0]
                    if not os.path.exists(os.path.normpath(os.path.join(REPO, os.path.dirname(doc), path))):
                        bad.append("%s:%d: %s" % (doc, n, target))
        self.assertEqual(bad, [], "links to files that are not in the repository")

    def test_file_paths_quoted_in_the_docs_exist(self):
        bad = []
        for doc in self.docs:
            for n, line in enumerate(read(doc).splitlines(), 1):
                for target in QUOTED_PATH.findall(line):
                    if target.startswith(("/", "~")) or "*" in target:
                        continue            # an absolute example path (/tmp/program.csr), not ours
                    if not resolves(target, doc):
                        bad.append("%s:%d: %s" % (doc, n, target))
        self.assertEqual(bad, [], "quoted paths that are not in the repository")

    def test_documents_named_anywhere_exist(self):
        """A document named in a comment, a docstring or a doc (DESIGN.md, STYLE.md ...) is shipped."""
        bad = []
        for path in self.text:
            for n, line in enumerate(read(path).splitlines(), 1):
                for name in DOC_NAME.findall(line):
                    if name not in self.basenames:
                        bad.append("%s:%d: %s" % (path, n, name))
        self.assertEqual(bad, [], "documents that are not in the repository")

    def test_nothing_points_outside_the_repository(self):
        bad = ["%s:%d" % (path, n) for path in self.text
               for n, line in enumerate(read(path).splitlines(), 1) if "../shared" in line]
        self.assertEqual(bad, [])

    def test_the_package_docstring_names_existing_modules(self):
        """vr_driver/__init__.py lists the core modules and the ROS edge; each one exists."""
        src = os.path.join(REPO, "vr_driver", "src", "vr_driver")
        doc = read("vr_driver/src/vr_driver/__init__.py").split('"""')[1]
        core = re.search(r"import no rospy[^:]*:(.*?)\.\s", doc, re.S).group(1)
        edge = re.search(r"ROS edge:(.*?)\.\s", doc, re.S).group(1)
        names = [n.strip() for n in re.split(r",|\band\b", re.sub(r"\(.*?\)", "", core + "," + edge)) if n.strip()]
        self.assertGreaterEqual(len(names), 10, names)
        missing = [n for n in names if not (os.path.isfile(os.path.join(src, n + ".py"))
                                            or os.path.isfile(os.path.join(src, n, "__init__.py")))]
        self.assertEqual(missing, [], "modules named in vr_driver/__init__.py that do not exist")


if __name__ == "__main__":
    unittest.main()

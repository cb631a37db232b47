"""The Khronos glTF validator on glTF/GLB files: the npm package ``gltf-validator`` (the reference validator,
compiled to JavaScript), installed on first use with ``npm`` into ``$JAXMOCAP_CACHE/npm`` (or
``~/.cache/jaxmocap/npm``) and run by ``node``. An export is clean when its report has no error, warning, info
or hint (``tests/test_export.py`` asserts it).

    python bench/checks/gltf_validate.py out/motion.glb [more.glb ...]  # counts per file; exit 1 unless clean
"""

import json
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

VERSION = "2.0.0-dev.3.10"
COUNTS = ("numErrors", "numWarnings", "numInfos", "numHints")

# process.argv: node, the package's folder, then the files; prints one JSON report per file, one per line.
_SCRIPT = """
const fs = require("fs");
const validator = require(process.argv[1]);
(async () => {
  for (const path of process.argv.slice(2)) {
    const report = await validator.validateBytes(new Uint8Array(fs.readFileSync(path)),
                                                 {uri: path, maxIssues: 0, writeTimestamp: false});
    console.log(JSON.stringify(report));
  }
})().catch((error) => { console.error(String(error)); process.exit(2); });
"""


def _cache_root() -> Path:
    env = os.environ.get("JAXMOCAP_CACHE")
    return Path(env) if env else Path.home() / ".cache" / "jaxmocap"


def validator_dir() -> Path:
    """The installed package's folder; installs it with npm (a few seconds, once) when absent."""
    root = _cache_root() / "npm" / f"gltf-validator-{VERSION}"
    package = root / "node_modules" / "gltf-validator"
    if (package / "package.json").is_file():
        return package
    npm = shutil.which("npm")
    if npm is None:
        raise RuntimeError("npm is not on PATH: install Node.js and npm (Debian: apt-get install nodejs npm) to run "
                           "the Khronos glTF validator")
    root.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=".tmp-", dir=root.parent))
    try:
        done = subprocess.run([npm, "install", "--prefix", str(tmp), "--no-audit", "--no-fund", "--loglevel=error",
                               f"gltf-validator@{VERSION}"], capture_output=True, text=True)
        if done.returncode != 0:
            raise RuntimeError(f"npm install gltf-validator@{VERSION} failed:\n{done.stdout}{done.stderr}")
        try:
            os.replace(tmp, root)
        except OSError:  # another process installed it meanwhile
            if not (package / "package.json").is_file():
                raise
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return package


def validate(*paths) -> list[dict]:
    """The validator's report (its JSON, as a dict) of each file; ``report["issues"]`` holds the counts
    ``numErrors``, ``numWarnings``, ``numInfos``, ``numHints`` and the ``messages``."""
    package = validator_dir()
    node = shutil.which("node") or shutil.which("nodejs")
    if node is None:
        raise RuntimeError("node is not on PATH: install Node.js to run the Khronos glTF validator")
    done = subprocess.run([node, "-e", _SCRIPT, str(package), *map(str, paths)], capture_output=True, text=True)
    if done.returncode != 0:
        raise RuntimeError(f"the glTF validator failed:\n{done.stdout}{done.stderr}")
    return [json.loads(line) for line in done.stdout.splitlines()]


def summary(report: dict) -> str:
    """``numErrors=0 numWarnings=0 ...`` and the distinct issue codes with their counts."""
    issues = report["issues"]
    codes = {}
    for message in issues["messages"]:
        codes[message["code"]] = codes.get(message["code"], 0) + 1
    text = " ".join(f"{k}={issues[k]}" for k in COUNTS)
    return text + "".join(f" {code}x{n}" for code, n in sorted(codes.items()))


def main(argv=None) -> int:
    paths = sys.argv[1:] if argv is None else argv
    if not paths:
        print(__doc__.strip().splitlines()[-1].strip(), file=sys.stderr)
        return 2
    clean = True
    for path, report in zip(paths, validate(*paths)):
        print(f"{path}: gltf-validator {report['validatorVersion']}: {summary(report)}")
        clean &= all(report["issues"][k] == 0 for k in COUNTS)
    return 0 if clean else 1


if __name__ == "__main__":
    sys.exit(main())

"""Print ``name==version`` for the lower bound of each named dependency in pyproject.toml.

``make test-lowest`` installs these so that CI also runs the suite against the
oldest numpy and scipy the declared ranges allow (the ranges are then true).
Usage: python .ci/lowest_pins.py numpy scipy
"""

import re
import sys
import tomllib
from pathlib import Path

deps = tomllib.loads((Path(__file__).resolve().parents[1] / "pyproject.toml").read_text())
pins = []
for name in sys.argv[1:]:
    spec = next((d for d in deps["project"]["dependencies"]
                 if re.match(rf"{re.escape(name)}\s*[<>=!~]", d)), None)
    low = spec and re.search(r">=\s*([0-9][^,\s]*)", spec)
    if not low:
        sys.exit(f"lowest_pins: pyproject.toml has no lower bound for {name}")
    pins.append(f"{name}=={low.group(1)}")
print(" ".join(pins))

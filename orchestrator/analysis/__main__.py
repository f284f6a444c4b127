"""Manual use: ``python -m orchestrator.analysis FRAMES_OR_RUN_DIR OUT_DIR [name | name:JSON] ...``

Example: ``python -m orchestrator.analysis runs/x/liggghts-abc out rdf 'd2min:{"interval": 0.01}'``
(default: every analysis with default options). Prints the summary as JSON.
"""
from __future__ import annotations

import json
import sys

from ..analysis_specs import parse_cli_spec
from . import ANALYSES, run_analyses


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if len(argv) < 2 or argv[0] in ("-h", "--help"):
        print(__doc__)
        print("analyses:", ", ".join(sorted(ANALYSES)))
        return 0 if argv and argv[0] in ("-h", "--help") else 2
    try:
        specs = [parse_cli_spec(a) for a in argv[2:] or sorted(ANALYSES)]
    except ValueError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    summary = run_analyses(argv[0], specs, argv[1])
    print(json.dumps({k: {kk: v[kk] for kk in ("status", "seconds", "files") if kk in v} | ({"error": v["error"]} if "error" in v else {})
                      for k, v in summary.items()}, indent=2, default=str))
    return 0 if all(v["status"] == "ok" for v in summary.values()) else 1


if __name__ == "__main__":
    raise SystemExit(main())

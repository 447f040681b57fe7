"""Regenerate ``src/biomorph/leaf/presets.json`` from ``../shared/data/leaves``.

Usage: .venv/bin/python bench/derive_leaf_presets.py [DATA_LEAVES_DIR]
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from biomorph.io.atomic import write_text
from biomorph.leaf.data import derive_presets, shared_leaves


def main() -> None:
    root = Path(sys.argv[1]) if len(sys.argv) > 1 else shared_leaves()
    if not root.is_dir():
        sys.exit(f"leaf data folder {root} is absent")
    presets = derive_presets(root)
    target = Path(__file__).resolve().parents[1] / "src" / "biomorph" / "leaf" / "presets.json"
    write_text(target, json.dumps(presets, indent=1) + "\n")
    target.chmod(0o644)  # atomic writes create 0600 temporaries
    for name, p in presets.items():
        print(f"{name}: L={p['length']} m, W={p['width']} m, source: {p['source']}")
    print(f"wrote {target}")


if __name__ == "__main__":
    main()

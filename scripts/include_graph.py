#!/usr/bin/python3
"""The folder-level include graph of raytime, and a check that its layers hold.

Layers (README "How we write code"): core <- formats <- stages (frontend, bootstrap, refine,
evaluate, splat) <- report <- pipelines <- cli. Stages never include one another (evaluate and
splat may read formats); report/ reads what the stages wrote through core's names and evaluate's
pose errors, never a stage adapter; cli reaches everything through pipelines/ (and report/); python/ (the
Python module) is a top layer beside cli; refine/'s rooms point one way (solve <- checks <-
recipes <- the entry at refine/'s top, REFINE_ROOMS); inside refine/ only refine.cc and the scene step above
it (scene.cc, the stage's work by image name) include the entry header refine/refine.h (the
others include refine/refine_types.h), so no arrow runs up.

  scripts/include_graph.py --check      exit 1 and name every include that breaks a layer
  scripts/include_graph.py --markdown   the graph as a Mermaid diagram with include counts
"""
import argparse
import collections
import os
import re
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
# Which folders each library folder may include (itself implied). tests/ and bench/ may use all.
ALLOWED = {
    "core": set(),
    "formats": {"core"},
    "frontend": {"core"},
    "bootstrap": {"core"},
    "refine": {"core"},
    "evaluate": {"core", "formats"},
    "splat": {"core", "formats"},
    "report": {"core", "formats", "evaluate"},
    "pipelines": {"core", "formats", "frontend", "bootstrap", "refine", "evaluate", "splat",
                  "report"},
    "cli": {"core", "pipelines", "report"},
    # The Python module is a top layer beside cli: it runs pipelines and calls the refine stage's
    # entry (refine/scene.h) and formats/ on arrays.
    "python": {"core", "formats", "frontend", "bootstrap", "refine", "evaluate", "splat", "report",
               "pipelines"},
    "testing": {"core", "refine", "evaluate"},
}
INCLUDE = re.compile(r'^\s*#\s*include\s+"([a-z_]+)/([^"]+)"')
# refine/ in rooms by job (issue 48): the solver, the checks on a solution, the recipes that
# compose passes and checks; the entry (refine.h, scene.h) above them. Which rooms each room may
# include (itself implied); every room may read the shared vocabulary refine/refine_types.h and
# refine/refine_options.h.
REFINE_ROOMS = {
    "solve": set(),
    "checks": {"solve"},
    "recipes": {"solve", "checks"},
    "": {"solve", "checks", "recipes"},
}
REFINE_VOCABULARY = {"refine/refine_types.h", "refine/refine_options.h"}


def refine_room(path):
    """The room of a path below refine/ ("" for the entry files at its top)."""
    parts = path.split("/")
    return parts[1] if len(parts) > 2 else ""


def includes():
    """(folder, file, included folder, included path) for every project include."""
    for folder in sorted(ALLOWED):
        for dirpath, _, names in os.walk(os.path.join(ROOT, folder)):
            for name in sorted(names):
                if not name.endswith((".h", ".cc")):
                    continue
                path = os.path.join(dirpath, name)
                with open(path, encoding="utf-8") as f:
                    for line in f:
                        m = INCLUDE.match(line)
                        if m and m.group(1) in ALLOWED:
                            yield folder, os.path.relpath(path, ROOT), m.group(1), \
                                m.group(1) + "/" + m.group(2)


def violations():
    found = []
    for folder, path, target, included in includes():
        if target != folder and target not in ALLOWED[folder]:
            found.append(f"{path}: includes {included} ({folder}/ may include "
                         f"{', '.join(sorted(ALLOWED[folder] | {folder}))})")
        if (included == "refine/refine.h" and path.startswith("refine/")
                and path not in ("refine/refine.cc", "refine/scene.cc")):
            found.append(f"{path}: includes the entry header refine/refine.h "
                         "(inside refine/ include refine/refine_types.h)")
        if folder == "refine" and target == "refine" and included not in REFINE_VOCABULARY:
            source_room, target_room = refine_room(path), refine_room(included)
            if target_room != source_room and target_room not in REFINE_ROOMS[source_room]:
                allowed = ", ".join("refine/" + r for r in sorted(REFINE_ROOMS[source_room]))
                found.append(f"{path}: includes {included} (refine/{source_room or ''} may "
                             f"include {allowed or 'no other room'}, and the vocabulary)")
    return found


def markdown():
    counts = collections.Counter((f, t) for f, _, t, _ in includes() if f != t)
    lines = ["```mermaid", "graph BT"]
    for (source, target), n in sorted(counts.items()):
        lines.append(f"  {source} -->|{n}| {target}")
    lines.append("```")
    return "\n".join(lines)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true", help="fail on an include across layers")
    parser.add_argument("--markdown", action="store_true", help="print the graph (Mermaid)")
    args = parser.parse_args()
    if args.markdown:
        print(markdown())
    if args.check:
        found = violations()
        for v in found:
            print(v, file=sys.stderr)
        if found:
            return 1
        print(f"include layers hold ({sum(1 for _ in includes())} project includes)")
    return 0


if __name__ == "__main__":
    sys.exit(main())

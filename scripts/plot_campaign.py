#!/usr/bin/python3
"""Plots of a campaign report (paper §4.8 "Basin of convergence", its basin figure).

Usage: plot_campaign.py REPORT_CELLS_CSV OUT_DIR

Reads the cells `raytime report` writes (report_cells.csv) and writes, from the cells pooled over
all scenes (scene "(all)"), per arm:
  success_vs_level.{png,svg}      success rate vs perturbation level with Wilson 95 % bands
  median_error_vs_level.{png,svg} median Sim(3) mean rotation error vs level, log-log
Levels are doubling, so both x axes are logarithmic; level 0 has no place on them and is drawn at
half the smallest positive level, labelled 0.

Exit status: 0 on success, 3 when matplotlib is not installed (the caller warns and carries on),
2 on a bad input file.
"""

import csv
import math
import os
import sys
import tempfile

EXIT_NO_MATPLOTLIB = 3
EXIT_BAD_INPUT = 2
ALL_SCENES = "(all)"  # CampaignReport::kAllScenes
# Errors below this are drawn at it on the log axis (a prior at level 0 scores ~1e-7°).
ERROR_FLOOR_DEG = 1e-3
# One marker per arm, so arms whose curves coincide (the prior and a control that returns it)
# stay distinguishable.
MARKERS = "osD^vPX*"


def read_pooled_cells(path):
    """{arm: [cell dict, ...] sorted by level} for the cells pooled over all scenes."""
    try:
        with open(path, newline="") as f:
            rows = list(csv.DictReader(f))
    except OSError as e:
        print(f"{path}: cannot read ({e.strerror})", file=sys.stderr)
        sys.exit(EXIT_BAD_INPUT)
    required = {"scene", "level_deg", "arm", "sim3_runs", "sim3_success_rate",
                "sim3_wilson_lower", "sim3_wilson_upper", "sim3_median_rotation_deg"}
    if rows and not required.issubset(rows[0]):
        missing = ", ".join(sorted(required - set(rows[0])))
        print(f"{path}: not a report_cells.csv (missing columns: {missing})", file=sys.stderr)
        sys.exit(EXIT_BAD_INPUT)
    arms = {}
    for line, row in enumerate(rows, start=2):
        if row["scene"] != ALL_SCENES or int(row["sim3_runs"] or 0) == 0:
            continue
        try:
            cell = {key: float(row[key]) if row[key] != "" else math.nan for key in required
                    if key not in ("scene", "arm")}
        except ValueError as e:
            print(f"{path}:{line}: {e}", file=sys.stderr)
            sys.exit(EXIT_BAD_INPUT)
        arms.setdefault(row["arm"], []).append(cell)
    for cells in arms.values():
        cells.sort(key=lambda cell: cell["level_deg"])
    return arms


def level_axis(arms):
    """x position of each level and the position standing in for level 0 (None without one)."""
    levels = sorted({cell["level_deg"] for cells in arms.values() for cell in cells})
    positive = [level for level in levels if level > 0]
    zero_x = (min(positive) / 2 if positive else 0.5) if 0.0 in levels else None
    return levels, zero_x


def x_of(level, zero_x):
    return zero_x if level == 0 else level


def label_levels(axes, levels, zero_x):
    axes.set_xscale("log")
    ticks = [x_of(level, zero_x) for level in levels]
    axes.set_xticks(ticks)
    axes.set_xticklabels([f"{level:g}" for level in levels])
    axes.minorticks_off()
    note = "" if zero_x is None else f"; level 0 drawn at {zero_x:g}"
    axes.set_xlabel(f"perturbation level (degrees, log scale{note})")


def save(figure, out_dir, stem):
    """Writes OUT_DIR/STEM.png and .svg, each to a temporary sibling renamed into place."""
    for extension in ("png", "svg"):
        target = os.path.join(out_dir, f"{stem}.{extension}")
        fd, temporary = tempfile.mkstemp(prefix=f".{stem}.", suffix=f".{extension}",
                                         dir=out_dir)
        os.close(fd)
        try:
            figure.savefig(temporary, format=extension, dpi=150, bbox_inches="tight")
            os.replace(temporary, target)
        except BaseException:
            os.unlink(temporary)
            raise


def main(argv):
    if len(argv) != 3:
        print(__doc__, file=sys.stderr)
        return EXIT_BAD_INPUT
    cells_path, out_dir = argv[1], argv[2]
    try:
        import matplotlib
    except ImportError:
        print("plot_campaign.py: matplotlib is not installed, no plots written "
              "(apt-get install python3-matplotlib)", file=sys.stderr)
        return EXIT_NO_MATPLOTLIB
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    arms = read_pooled_cells(cells_path)
    if not arms:
        print(f"{cells_path}: no scored cells, no plots written", file=sys.stderr)
        return 0
    levels, zero_x = level_axis(arms)

    # (a) success rate with Wilson 95 % bands.
    figure, axes = plt.subplots(figsize=(6, 4))
    for index, (arm, cells) in enumerate(arms.items()):
        x = [x_of(cell["level_deg"], zero_x) for cell in cells]
        line, = axes.plot(x, [cell["sim3_success_rate"] for cell in cells],
                          marker=MARKERS[index % len(MARKERS)], fillstyle="none", label=arm)
        axes.fill_between(x, [cell["sim3_wilson_lower"] for cell in cells],
                          [cell["sim3_wilson_upper"] for cell in cells],
                          color=line.get_color(), alpha=0.15, linewidth=0)
    label_levels(axes, levels, zero_x)
    axes.set_ylim(-0.02, 1.02)
    axes.set_ylabel("success rate (Wilson 95 % band)")
    axes.set_title("Success (mean rotation error after Sim(3) below threshold) vs level",
                   fontsize=10)
    axes.legend(fontsize=8)
    axes.grid(alpha=0.3)
    save(figure, out_dir, "success_vs_level")
    plt.close(figure)

    # (b) median error, log-log; the dashed diagonal is "returned the prior unchanged".
    figure, axes = plt.subplots(figsize=(6, 4))
    for index, (arm, cells) in enumerate(arms.items()):
        x = [x_of(cell["level_deg"], zero_x) for cell in cells]
        y = [max(cell["sim3_median_rotation_deg"], ERROR_FLOOR_DEG) for cell in cells]
        axes.plot(x, y, marker=MARKERS[index % len(MARKERS)], fillstyle="none", label=arm)
    positive = [level for level in levels if level > 0]
    if positive:
        axes.plot(positive, positive, linestyle="--", color="0.5", linewidth=1,
                  label="error = level")
    label_levels(axes, levels, zero_x)
    axes.set_yscale("log")
    axes.set_ylabel("median rotation error after Sim(3) (degrees)")
    axes.set_title(f"Median error vs level (below {ERROR_FLOOR_DEG:g}° drawn at {ERROR_FLOOR_DEG:g}°)",
                   fontsize=10)
    axes.legend(fontsize=8)
    axes.grid(alpha=0.3, which="both")
    save(figure, out_dir, "median_error_vs_level")
    plt.close(figure)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))

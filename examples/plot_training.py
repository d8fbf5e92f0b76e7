"""Training curves from examples/ppo.py logs: success and return against env steps and against
wall time, one PNG per log (or one for several logs, overlaid, with --out).

    pip install matplotlib
    python examples/plot_training.py runs/PickCube-v1__panda__pd_joint_delta_pos__1/log.csv
    python examples/plot_training.py runs/*/log.csv --out curves.png
    python examples/plot_training.py a/log.csv b/log.csv --labels joint ee --out both.png

Each figure has four panels: success rate (train: episodes that ended in the iteration; eval:
fixed seeds, mean action) and mean episode return (train and eval), each against env steps
and against wall-clock minutes. The title gives the measured throughput and its split into
simulation and learner time.
"""

import argparse
import csv
import os


def read_log(path):
    cols = {}
    with open(path, newline="") as f:
        for row in csv.DictReader(f):
            for k, v in row.items():
                cols.setdefault(k, []).append(float(v) if v not in ("", None) else None)
    if "env_steps" not in cols:
        raise SystemExit(f"{path}: not an examples/ppo.py log (no env_steps column)")
    return cols


def series(cols, x, y):
    pts = [(a, b) for a, b in zip(cols[x], cols[y]) if a is not None and b is not None]
    return [a for a, _ in pts], [b for _, b in pts]


def label_of(path):
    return os.path.basename(os.path.dirname(os.path.abspath(path))) or path


def plot(paths, out, labels=None):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 2, figsize=(12, 8))
    notes = []
    for k, path in enumerate(paths):
        c = read_log(path)
        c["wall_min"] = [None if w is None else w / 60.0 for w in c["wall_time"]]
        name = labels[k] if labels else label_of(path)
        for row, (metric, what) in enumerate((("success", "success rate"),
                                              ("return", "mean return"))):
            for col, (x, xlabel) in enumerate((("env_steps", "env steps"),
                                               ("wall_min", "wall time (min)"))):
                ax = axes[row][col]
                xs, ys = series(c, x, f"train_{metric}")
                line, = ax.plot(xs, ys, alpha=0.5, label=f"{name} train")
                xs, ys = series(c, x, f"eval_{metric}")
                ax.plot(xs, ys, "o-", color=line.get_color(), label=f"{name} eval")
                ax.set_xlabel(xlabel)
                ax.set_ylabel(what)
                if metric == "success":
                    ax.set_ylim(-0.02, 1.02)
                ax.grid(alpha=0.3)
        steps, wall = c["env_steps"][-1], c["wall_time"][-1]
        sim, learn = c["sim_time"][-1], c["learner_time"][-1]
        notes.append(f"{name}: {steps:.0f} steps in {wall / 60:.1f} min = {steps / wall:.0f} "
                     f"steps/s (sim {sim / wall:.0%}, learner {learn / wall:.0%})")
    axes[0][0].legend(fontsize=8)
    fig.suptitle("\n".join(notes), fontsize=9)
    fig.tight_layout()
    fig.savefig(out, dpi=100)
    plt.close(fig)
    print(out)


def main():
    p = argparse.ArgumentParser(description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("logs", nargs="+", help="log.csv files of examples/ppo.py")
    p.add_argument("--out", help="one PNG for all logs (default: curves.png next to each log)")
    p.add_argument("--labels", nargs="+", help="legend names of the logs (default: run directories)")
    a = p.parse_args()
    if a.labels and len(a.labels) != len(a.logs):
        p.error(f"--labels has {len(a.labels)} names for {len(a.logs)} logs")
    if a.out:
        plot(a.logs, a.out, a.labels)
    else:
        for path in a.logs:
            plot([path], os.path.join(os.path.dirname(os.path.abspath(path)), "curves.png"))


if __name__ == "__main__":
    main()

"""Behaviour cloning from demonstrations, such as noise-injected solver episodes (DART), into
the same ONNX policy files as examples/ppo.py (docs/training.md, "Cloning from noisy
demonstrations"):

    mjskill rollout --policy solver --action-noise 0.05 --episodes 200 --out demos.mcap
    python examples/imitate.py --demos demos.mcap
    mjskill eval --policy runs/<run>/best.onnx --episodes 100 --seed 10000

An MLP (256x256 tanh by default) learns, by mean squared error, the expert's own action (a
recording's ``expert_action``; the executed action where a file has none) from the state the
env was in, over every recorded step of the successful episodes (``--include-failed``: of all
episodes). Observations are normalised
by the demos' statistics (each entry's std at least 0.01, clipped to ±10), labels by theirs;
both are folded into the exported graph, so the file takes the env's observation and returns
its action. The actor does not see the gripper joints' velocities (``--gripper-qvel
observe`` to show them), as in ppo.py.

``--relative-labels`` (joint position modes, e.g. pd_joint_pos): the network learns each
absolute joint target minus the joint's measured position (the observation's agent/qpos
entry), and the exported graph adds that position back, so the file still returns the env's
absolute targets. Which action entries are a joint's absolute target is measured on the env:
after one step, the joint's drive target is the action entry itself.

``--dagger-rounds R`` (DAgger): after the cloning epochs, each round runs the policy on
``--dagger-episodes`` episodes (seeds from ``--dagger-seed``, held out from the evaluation;
up to 64 at once in the vector env, on ``--num-threads`` threads), asks the state expert for
its action at every state the policy visits (``envs.expert_actions()``, all the envs at once
on their threads: a function of the state, docs/solvers.md §8.2), adds
those (state, label) pairs to the data and trains ``--dagger-epochs`` more epochs on all of
it. With ``--dagger-beta B`` the expert's own action is executed instead of the policy's
with probability B^round. The normalisation keeps the demos' statistics. A resumed run goes
on with the next round (a round stopped during its epochs keeps its data, not the epochs it
had left).

The run directory (``--out``, default runs/<env>__<robot>__<mode>__imitate<seed>) holds, as
ppo.py's: policy.onnx (the latest), best.onnx (the best evaluation), their weights (.pt),
checkpoint.pt (for ``--resume``) and log.csv, one row per epoch (epoch, samples so far,
wall_time, train_loss) and one per evaluation (eval_success, eval_return, eval_time): the
policy on ``--num-eval-envs`` episodes in mjskill on seeds from ``--eval-seed`` (held out: a
seed of the demos is refused), the mean action, an episode ended at its first success.
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import gymnasium as gym
import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from training import rundir  # noqa: E402
from training.args import (  # noqa: E402
    changed_options, command_line, finite_at_least_zero, finite_positive, non_negative,
    nonempty, number_in, positive, same_dir, with_values, without_option)
from training.evaluate import run_episodes  # noqa: E402
from training.export import metadata, save_policy  # noqa: E402

#: How this script names itself in the shared modules' messages.
SCRIPT = "examples/imitate.py"

#: The least variance of an observation entry in the demos' statistics (std 0.01), as ppo.py
#: --demos: an entry the demos never vary would otherwise turn the smallest deviation into a
#: clipped ±10 input.
OBS_VAR_FLOOR = 1e-4
#: The least std of a label entry (a label the demos never vary is then learned as 0 there).
LABEL_STD_FLOOR = 1e-6
#: Observations are clipped to ±this after normalising (in the exported graph too).
OBS_CLIP = 10.0

#: Options a resumed run cannot change: they define the network or its data.
RUN_DEFINING = ("env_id", "robot", "control_mode", "seed", "hidden", "demos",
                "include_failed", "relative_labels", "absolute_gripper", "gripper_qvel",
                "hide_obs", "batch_size", "obs_noise",
                "dagger_episodes", "dagger_beta", "dagger_seed")

#: log.csv's columns.
LOG_HEADER = ["epoch", "samples", "wall_time", "train_loss", "eval_success", "eval_return",
              "eval_time"]

#: What a checkpoint of this script holds.
CHECKPOINT_KEYS = ("net", "optimizer", "obs_mean", "obs_std", "label_mean", "label_std",
                   "residual", "hidden_obs", "argv", "command", "epoch", "samples", "best",
                   "resumes", "resume_commands", "times", "torch_rng")


def parse_args(argv=None, check=True):
    p = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--demos", metavar="FILE", nargs="+", default=None,
                   help="demonstrations: mjskill rollout recordings (.mcap; with "
                        "--action-noise they carry the expert's labels) or ManiSkill "
                        "trajectory files (.h5 with their .json); successful episodes only")
    p.add_argument("--env-id", default=None, help="mjskill env id (default: the demos')")
    p.add_argument("--robot", default=None, help="robot uid (default: the demos')")
    p.add_argument("--control-mode", default=None, help="control mode (default: the demos')")
    p.add_argument("--seed", type=int, default=1, help="torch's seed (initialisation, batches)")
    p.add_argument("--hidden", type=positive, nargs="+", default=[256, 256],
                   help="hidden layer sizes (tanh between layers)")
    p.add_argument("--epochs", type=positive, default=100, help="passes over the demos")
    p.add_argument("--batch-size", type=positive, default=256)
    p.add_argument("--learning-rate", type=finite_positive, default=1e-3, help="Adam's")
    p.add_argument("--obs-noise", type=finite_at_least_zero, default=0.0,
                   help="std of Gaussian noise added to the (normalised) observations while "
                        "learning")
    p.add_argument("--include-failed", action="store_true",
                   help="also clone the failed episodes (their labels are the expert's too, "
                        "but an expert that lost its object may label the states after that "
                        "badly); by default only successful episodes are used")
    p.add_argument("--relative-labels", action="store_true",
                   help="learn joint targets relative to the measured joint positions (joint "
                        "position modes); the exported file adds the positions back")
    p.add_argument("--absolute-gripper", action="store_true",
                   help="with --relative-labels: learn the gripper joints' targets as they "
                        "are (a relative open-or-close label averages to 'stay' where the "
                        "expert lets go)")
    p.add_argument("--gripper-qvel", choices=("hide", "observe"), default="hide",
                   help="hide the gripper joints' velocities from the policy (default; "
                        "PhysX reports a residual there, docs/outcome-physics.md) or observe them")
    p.add_argument("--hide-obs", metavar="INDEX", type=non_negative, nargs="+", default=[],
                   help="observation entries the policy does not see, by index into the state "
                        "observation (e.g. the Fetch's base and head joints, whose positions "
                        "and velocities the task does not need); with --relative-labels a "
                        "hidden joint position's target is learned absolute")
    p.add_argument("--dagger-rounds", type=non_negative, default=0,
                   help="DAgger rounds after the cloning epochs (0: cloning only); each runs "
                        "the policy, labels its states with the env's state expert and trains "
                        "on everything so far")
    p.add_argument("--dagger-episodes", type=positive, default=100,
                   help="episodes the policy runs per DAgger round")
    p.add_argument("--dagger-epochs", type=positive, default=25,
                   help="epochs over all the data after each DAgger round")
    p.add_argument("--dagger-beta", type=number_in(0.0, 1.0, " (a probability)"), default=0.0,
                   help="round r executes the expert's action instead of the policy's with "
                        "probability beta^r (0: the policy's always)")
    p.add_argument("--dagger-seed", type=int, default=2**30,
                   help="seed of the first DAgger episode (round r, episode i: seed + (r - 1) "
                        "x --dagger-episodes + i); held out from the evaluation")
    p.add_argument("--eval-every", type=positive, default=25,
                   help="evaluate every N epochs (and after the last)")
    p.add_argument("--num-eval-envs", type=positive, default=100,
                   help="evaluation episodes (seeds --eval-seed, --eval-seed + 1, ...)")
    p.add_argument("--eval-seed", type=int, default=2**31,
                   help="seed of the first evaluation episode; held out: no demo episode may "
                        "have a seed in the evaluation's range")
    p.add_argument("--num-threads", type=positive, default=None,
                   help="threads of the evaluation's native vector env (default: the cores)")
    p.add_argument("--torch-threads", type=positive, default=os.cpu_count() or 1)
    p.add_argument("--max-minutes", type=finite_positive, default=None,
                   help="stop after this much wall time (the policy is evaluated and saved)")
    p.add_argument("--out", type=nonempty, default=None,
                   help="run directory (default runs/<env>__<robot>__<mode>__imitate<seed>)")
    p.add_argument("--resume", metavar="RUN_DIR", default=None,
                   help="continue the run in RUN_DIR from its checkpoint.pt with its saved "
                        "options; options given here override them (a larger --epochs, say), "
                        f"except those that define the run ({', '.join(RUN_DEFINING)})")
    args = p.parse_args(argv)
    if not check:
        return args
    if args.resume is not None:
        if not os.path.isfile(os.path.join(args.resume, "checkpoint.pt")):
            p.error(f"--resume {args.resume}: no checkpoint.pt there (a run writes one at every "
                    "evaluation and when it stops)")
        if args.out is not None and not same_dir(args.out, args.resume):
            p.error(f"--out {args.out} with --resume {args.resume}: a resumed run continues in "
                    "its own directory; leave --out out")
        return args
    if not args.demos:
        p.error("--demos is required (the recordings to clone), unless --resume")
    if args.absolute_gripper and not args.relative_labels:
        p.error("--absolute-gripper keeps the gripper's labels absolute under --relative-labels; "
                "without --relative-labels every label is absolute already")
    if not 0 <= args.eval_seed or args.eval_seed + args.num_eval_envs - 1 > 2**32 - 1:
        p.error(f"--eval-seed {args.eval_seed} with --num-eval-envs {args.num_eval_envs}: "
                "evaluation seeds must lie in 0..=4294967295")
    dagger_end = args.dagger_seed + args.dagger_rounds * args.dagger_episodes
    if args.dagger_rounds and not (0 <= args.dagger_seed and dagger_end - 1 <= 2**32 - 1):
        p.error(f"--dagger-seed {args.dagger_seed} with {args.dagger_rounds} rounds of "
                f"{args.dagger_episodes} episodes: DAgger seeds must lie in 0..=4294967295")
    if args.dagger_rounds and (args.dagger_seed < args.eval_seed + args.num_eval_envs
                               and args.eval_seed < dagger_end):
        p.error(f"--dagger-seed {args.dagger_seed}: the DAgger episodes' seeds "
                f"({args.dagger_seed}..{dagger_end - 1}) overlap the evaluation's "
                f"({args.eval_seed}..{args.eval_seed + args.num_eval_envs - 1}); the "
                "evaluation must be held out")
    if args.out is not None and os.path.exists(args.out) and not os.path.isdir(args.out):
        p.error(f"--out {args.out} exists and is not a directory; the run directory holds "
                "policy.onnx, best.onnx, checkpoints and log.csv")
    return args


def resumed_args(argv):
    """The options of a resumed run: the saved run's, then those given now. Returns (args,
    checkpoint)."""
    given = parse_args(argv)
    ckpt = rundir.load_checkpoint(given.resume, CHECKPOINT_KEYS, SCRIPT)
    saved_argv = list(ckpt["argv"])
    # The options given now, without --resume DIR (or --resume=DIR).
    rest = without_option(list(sys.argv[1:] if argv is None else argv), "--resume")
    args = parse_args(saved_argv + rest, check=False)
    saved = parse_args(saved_argv, check=False)

    def differs(k, a, b):
        if k == "demos" and a and b:  # the same files, relative or absolute
            return [os.path.abspath(x) for x in a] != [os.path.abspath(x) for x in b]
        return a != b

    changed = changed_options(args, saved, RUN_DEFINING, differs)
    if changed:
        sys.exit(f"error: --resume {given.resume}: {', '.join(changed)} cannot change when a "
                 "run continues (they define its network or its data)")
    args.resume = given.resume
    args.out = given.resume
    return args, ckpt


def absolute_joint_targets(env):
    """For every action entry of ``env`` (a single mjskill env, state observations): the index
    of the observation entry holding the position of the joint whose absolute target the entry
    is, or None. Measured: after a reset and one step with distinct actions within the bounds,
    an entry is joint j's absolute target when j's drive target is the entry's value; the
    joint's position is then agent/qpos[j], at the start of the state observation (checked
    against the state dict)."""
    space = env.action_space
    n = space.shape[0]
    probe = np.zeros(n, np.float32)
    for k in range(n):
        lo, hi = float(space.low[k]), float(space.high[k])
        if np.isfinite(lo) and np.isfinite(hi):
            probe[k] = lo + (hi - lo) * (0.25 + 0.5 * (k + 1) / (n + 1))
        else:
            probe[k] = 0.1234 + 0.0137 * k
    env.reset(seed=0)
    obs, *_ = env.step(probe)
    sd = env.unwrapped.get_state_dict()
    targets = np.asarray(sd["drive"]["target_qpos"], np.float64)
    art = np.asarray(sd["articulations"][env.unwrapped.robot_uids], np.float64)
    q = len(targets)
    qpos = art[13:13 + q]
    if not np.array_equal(np.asarray(obs[:q], np.float32), qpos.astype(np.float32)):
        raise ValueError(f"the state observation of {env.unwrapped.env_id} does not start with "
                         "agent/qpos; relative labels need the joint positions there")
    out = []
    for k in range(n):
        hits = np.flatnonzero(targets.astype(np.float32) == probe[k])
        out.append(int(hits[0]) if len(hits) else None)
    return out


#: Envs a DAgger round steps at once (fewer when the round has fewer episodes).
DAGGER_ENVS = 64


def collect_dagger(make_vec, act, first_seed, episodes, max_steps, beta, rng):
    """One DAgger round on the vector env ``make_vec()`` (N envs): ``episodes`` episodes (seeds
    ``first_seed``, ``first_seed + 1``, ...), N at a time, each until its first success or
    ``max_steps``, executing ``act``'s action (with probability ``beta`` the expert's instead,
    drawn from ``rng`` per env and step) and recording every visited state with the state
    expert's label for it. The N envs are labelled at once, on the env threads
    (``MjskillVectorEnv.expert_actions``: the single env's ``expert_action``, bit for bit).
    Returns (observations, labels, successes), the episodes in seed order."""
    envs = make_vec()
    n = envs.num_envs
    obs_seen = [[] for _ in range(episodes)]
    labels_seen = [[] for _ in range(episodes)]
    successes = 0
    try:
        for start in range(0, episodes, n):
            # Env i runs episode start + i (seed first_seed + start + i); the envs past the
            # round's last episode, and every env after its episode ends, step unrecorded.
            obs, _ = envs.reset(seed=first_seed + start)
            live = np.arange(n) < episodes - start
            for _ in range(max_steps):
                labels = envs.expert_actions()
                for i in np.flatnonzero(live):
                    obs_seen[start + i].append(np.asarray(obs[i], np.float64))
                    labels_seen[start + i].append(np.asarray(labels[i], np.float64))
                expert = rng.random(n) < beta
                a = np.where(expert[:, None], labels, act(np.asarray(obs))).astype(np.float32)
                obs, _, terminated, truncated, _ = envs.step(a)
                successes += int(np.count_nonzero(live & terminated))
                live &= ~(terminated | truncated)
                if not live.any():
                    break
    finally:
        envs.close()
    return (np.array([o for ep in obs_seen for o in ep]),
            np.array([label for ep in labels_seen for label in ep]), successes)


def main(argv=None):
    args = parse_args(argv)
    ckpt = None
    run_lock = (rundir.hold_run_dir(args.resume or args.out, SCRIPT)
                if (args.resume or args.out) else None)
    if args.resume is not None:
        args, ckpt = resumed_args(argv)
    from demos import DemoError, check_unchanged, fingerprints, load, mjskill_spaces

    try:
        if ckpt is not None and ckpt.get("demo_files"):
            # The files the run started with, unchanged (a checkpoint written before
            # fingerprints were kept has none: its files are taken as they are).
            check_unchanged(ckpt["demo_files"], args.resume)
        # Every file is read and checked before the evaluation's envs are built (one env is
        # made for the spaces the demos must fit).
        demos = load(args.demos, args.env_id, args.robot, args.control_mode,
                     trainer="imitate.py", keep_failed=args.include_failed,
                     spaces=mjskill_spaces)
        demo_files = fingerprints(args.demos)
    except DemoError as e:
        sys.exit(f"error: {e}")
    for note in demos.notes:
        print(f"note: {note}", flush=True)
    args.env_id = demos.env_id
    args.robot = args.robot or demos.robot
    args.control_mode = args.control_mode or demos.control_mode
    eval_seeds = range(args.eval_seed, args.eval_seed + args.num_eval_envs)
    overlap = sorted(s for s in demos.seeds if s in eval_seeds)
    if overlap:
        sys.exit(f"error: --eval-seed {args.eval_seed} with --num-eval-envs "
                 f"{args.num_eval_envs} evaluates on seeds the demos were recorded with "
                 f"({', '.join(map(str, overlap[:5]))}{', ...' if len(overlap) > 5 else ''}); "
                 "the evaluation must be held out: choose seeds the demos do not use")

    import torch
    import torch.nn as nn

    import mjskill

    torch.manual_seed(args.seed)
    torch.set_num_threads(args.torch_threads)
    num_threads = args.num_threads or os.cpu_count() or 1
    gid = f"mjskill/{args.env_id}"
    kw = dict(robot_uids=args.robot, control_mode=args.control_mode, obs_mode="state")

    # Each evaluation episode is its seed's, PegInsertionSide-v1's shapes included.
    def make_eval_envs():
        return gym.make_vec(gid, num_envs=args.num_eval_envs, num_threads=num_threads,
                            reconfiguration_freq=1, **kw)

    probe_env = gym.make(gid, **kw)
    try:
        base = probe_env.unwrapped
        robot, mode, max_steps = base.robot_uids, base.control_mode, probe_env.spec.max_episode_steps
        obs_dim = probe_env.observation_space.shape[0]
        bad = [i for i in args.hide_obs if i >= obs_dim]
        if bad:
            sys.exit(f"error: --hide-obs {' '.join(map(str, bad))}: {args.env_id} with {robot} "
                     f"in {mode} observes {obs_dim} values (indices 0..{obs_dim - 1})")
        act_dim = probe_env.action_space.shape[0]
        low = probe_env.action_space.low.astype(np.float32)
        high = probe_env.action_space.high.astype(np.float32)
        grip = list(base.gripper_qvel_obs)
        residual = None
        if args.dagger_rounds:
            probe_env.reset(seed=0)
            try:
                probe_env.unwrapped.expert_action()
            except ValueError as e:
                sys.exit(f"error: --dagger-rounds {args.dagger_rounds}: {e}")
        if args.relative_labels and ckpt is None:
            residual = absolute_joint_targets(probe_env)
            if args.absolute_gripper:
                gripper = set(base._native.spec()["gripper_joints"])
                residual = [None if i in gripper else i for i in residual]
            # A position the policy does not see cannot be added back to its target.
            residual = [None if i in args.hide_obs else i for i in residual]
            if all(i is None for i in residual):
                sys.exit(f"error: --relative-labels: no action entry of {robot} in {mode} is "
                         "a joint's absolute position target; relative labels are for joint "
                         "position modes such as pd_joint_pos (delta modes are relative "
                         "already)")
    finally:
        probe_env.close()
    from demos import replay_missing_obs

    try:
        # ManiSkill files without observations: replayed by their actions here first.
        replay_missing_obs(demos, lambda: gym.make(gid, **kw))
    except DemoError as e:
        sys.exit(f"error: {e}")
    if demos.obs_dim != obs_dim:
        sys.exit(f"error: --demos {' '.join(args.demos)}: observations of {demos.obs_dim} "
                 f"values, but {args.env_id} with {robot} in {mode} observes {obs_dim}")
    out = args.out or os.path.join("runs", f"{args.env_id}__{robot}__{mode}__imitate{args.seed}")
    if run_lock is None:
        run_lock = rundir.hold_run_dir(out, SCRIPT)
    run_argv = list(ckpt["argv"]) if ckpt is not None else list(
        sys.argv[1:] if argv is None else argv)
    # The policy files' training_command is the command as typed (relative demo paths
    # included); the checkpoint's argv, which --resume runs again, names the demos by
    # absolute path.
    command = ckpt["command"] if ckpt is not None else command_line(run_argv)
    if ckpt is None:
        # The demo files by absolute path: a resume from another directory finds them.
        run_argv = with_values(run_argv, "--demos", [os.path.abspath(f) for f in args.demos])
    if ckpt is not None:
        rundir.check_checkpoint_is_the_runs(out, command, robot, mode)
    hidden = sorted(set((grip if args.gripper_qvel == "hide" else []) + list(args.hide_obs)))

    # The data: every recorded step of the successful episodes, labelled with the expert's
    # own action where recorded.
    x_raw = demos.all_obs.astype(np.float64)
    y = demos.all_labels.astype(np.float64)
    if ckpt is None:
        if residual is not None:
            for k, i in enumerate(residual):
                if i is not None:
                    y[:, k] -= x_raw[:, i]
        obs_mean = x_raw.mean(0)
        obs_std = np.sqrt(np.maximum(x_raw.var(0), OBS_VAR_FLOOR))
        label_mean = y.mean(0)
        label_std = np.maximum(y.std(0), LABEL_STD_FLOOR)
    else:
        obs_mean, obs_std = ckpt["obs_mean"].numpy(), ckpt["obs_std"].numpy()
        label_mean, label_std = ckpt["label_mean"].numpy(), ckpt["label_std"].numpy()
        residual = [None if i < 0 else int(i) for i in ckpt["residual"].tolist()] \
            if len(ckpt["residual"]) else None
        if residual is not None:
            for k, i in enumerate(residual):
                if i is not None:
                    y[:, k] -= x_raw[:, i]
    keep = torch.ones(obs_dim)
    keep[hidden] = 0.0

    def relative(obs, labels):
        """Labels as the network learns them: less the joint positions with relative labels."""
        labels = labels.astype(np.float64)
        for k, i in enumerate(residual or []):
            if i is not None:
                labels[:, k] -= obs[:, i]
        return labels

    # DAgger's (state, expert label) pairs so far, raw (a resumed run's from its checkpoint).
    dagger_obs = np.zeros((0, obs_dim))
    dagger_labels = np.zeros((0, act_dim))
    dagger_round = 0
    if ckpt is not None and "dagger_round" in ckpt:
        dagger_obs = ckpt["dagger_obs"].numpy()
        dagger_labels = ckpt["dagger_labels"].numpy()
        dagger_round = int(ckpt["dagger_round"])
    demo_steps = len(x_raw)

    def training_data():
        """The normalised inputs and targets: the demos' steps, then DAgger's."""
        xr = np.concatenate([x_raw, dagger_obs])
        yr = np.concatenate([y, relative(dagger_obs, dagger_labels)])
        xt = torch.as_tensor(np.clip((xr - obs_mean) / obs_std, -OBS_CLIP, OBS_CLIP),
                             dtype=torch.float32) * keep
        return xt, torch.as_tensor((yr - label_mean) / label_std, dtype=torch.float32)

    x, t = training_data()
    n = x.shape[0]
    labelled = demos.labelled
    print(f"{args.env_id} {robot} {mode}: {len(demos.episodes)} episodes "
          f"({demos.kept_failed} of them failed; {labelled} with expert labels), {n} steps "
          f"from {len(demos.files)} file(s); {demos.skipped_failed} failed episodes left out"
          + (f"; relative labels on action entries "
             f"{[k for k, i in enumerate(residual) if i is not None]}" if residual else ""),
          flush=True)

    layers, n_in = [], obs_dim
    for h in args.hidden:
        layers += [nn.Linear(n_in, h), nn.Tanh()]
        n_in = h
    net = nn.Sequential(*layers, nn.Linear(n_in, act_dim))
    opt = torch.optim.Adam(net.parameters(), lr=args.learning_rate)
    res_k = [k for k, i in enumerate(residual or []) if i is not None]
    res_i = [i for i in (residual or []) if i is not None]

    def act(obs):
        """The policy's action for a batch of raw observations, as the exported file computes
        it (clipped to the action space, as mjskill eval clips it)."""
        xo = np.clip((obs - obs_mean) / obs_std, -OBS_CLIP, OBS_CLIP)
        with torch.no_grad():
            a = net(torch.as_tensor(xo, dtype=torch.float32) * keep).numpy()
        a = a * label_std.astype(np.float32) + label_mean.astype(np.float32)
        if res_k:
            a[:, res_k] += obs[:, res_i]
        return np.clip(a, low, high).astype(np.float32)

    def exported_layers():
        """The network as policy_onnx's layers: weights [in, out], the hidden inputs' rows
        zeroed (the network multiplies them by zero), the label statistics folded into the
        last layer."""
        lins = [m for m in net if isinstance(m, nn.Linear)]
        out_layers = [(m.weight.detach().numpy().T.astype(np.float64),
                       m.bias.detach().numpy().astype(np.float64)) for m in lins]
        out_layers[0][0][hidden] = 0.0
        w, b = out_layers[-1]
        out_layers[-1] = (w * label_std, b * label_std + label_mean)
        return out_layers

    def weights():
        return {"net": {k: v.clone() for k, v in net.state_dict().items()},
                "obs_mean": torch.from_numpy(np.asarray(obs_mean, np.float64)),
                "obs_std": torch.from_numpy(np.asarray(obs_std, np.float64)),
                "label_mean": torch.from_numpy(np.asarray(label_mean, np.float64)),
                "label_std": torch.from_numpy(np.asarray(label_std, np.float64)),
                "residual": torch.tensor([-1 if i is None else i for i in residual or []],
                                         dtype=torch.int64),
                "hidden_obs": torch.tensor(hidden, dtype=torch.int64)}

    def save(tag, eval_success):
        meta = metadata(
            args.env_id, robot, mode, command,
            "behaviour cloning (examples/imitate.py)"
            + (f", then DAgger ({dagger_round} rounds of {args.dagger_episodes} episodes, "
               f"beta {args.dagger_beta:g}; labels from the state expert)"
               if dagger_round else "")
            + (", labels relative to the measured joint positions" if residual else ""),
            n, eval_success, mjskill.__version__, hidden, resumes, resume_commands,
            demos=(f"{len(demos.episodes)} episodes ({demos.kept_failed} failed, {labelled} "
                   f"with expert labels), {n} steps: "
                   + " ".join(os.path.basename(f) for f in demos.files)),
            epochs=str(epoch),
            expert_labels=str(sum(len(e.actions) for e in demos.episodes
                                  if e.labels is not None) + len(dagger_obs)),
            # How the demos were recorded (each file's own command, where it keeps one): with
            # training_command, the whole recipe of the file.
            **({"demos_command": " ; ".join(demos.commands)} if demos.commands else {}))
        path = save_policy(out, tag, exported_layers(), obs_mean, obs_std, meta,
                           obs_clip=OBS_CLIP, residual=residual)
        rundir.save_torch(os.path.join(out, f"{tag}.pt"), weights())
        return path

    def checkpoint(next_epoch):
        state = weights()
        state.update(optimizer=opt.state_dict(), argv=run_argv, command=command,
                     demo_files=demo_files,
                     epoch=next_epoch, samples=samples, best=best, resumes=resumes,
                     resume_commands=resume_commands,
                     times=dict(wall=time.perf_counter() - t_start, eval=eval_time),
                     torch_rng=torch.get_rng_state(),
                     dagger_obs=torch.from_numpy(np.asarray(dagger_obs, np.float64)),
                     dagger_labels=torch.from_numpy(np.asarray(dagger_labels, np.float64)),
                     dagger_round=dagger_round)
        rundir.save_torch(os.path.join(out, "checkpoint.pt"), state)

    def evaluate():
        envs = make_eval_envs()
        try:
            return run_episodes(envs, act, args.eval_seed, max_steps)
        finally:
            envs.close()

    log_path = os.path.join(out, "log.csv")
    samples, first_epoch, best, eval_time = 0, 1, None, 0.0
    resumes, resume_commands = [], []
    if ckpt is not None:
        net.load_state_dict(ckpt["net"])
        opt.load_state_dict(ckpt["optimizer"])
        for g in opt.param_groups:
            g["lr"] = args.learning_rate
        first_epoch, samples, best = int(ckpt["epoch"]), int(ckpt["samples"]), ckpt["best"]
        resumes = list(ckpt["resumes"]) + [first_epoch - 1]
        resume_commands = list(ckpt["resume_commands"]) + [command_line()]
        eval_time = ckpt["times"]["eval"]
        torch.set_rng_state(ckpt["torch_rng"])
        log, writer = rundir.start_log(log_path, LOG_HEADER, (first_epoch, samples),
                                       "imitate.py")
        t_start = time.perf_counter() - ckpt["times"]["wall"]
    else:
        log, writer = rundir.start_log(log_path, LOG_HEADER, None, "imitate.py")
        t_start = time.perf_counter()
    print(f"obs {obs_dim}, act {act_dim}; MLP {args.hidden}, {args.epochs} epochs of {n} "
          f"samples, batches of {args.batch_size}"
          f"{f', resumed at epoch {first_epoch}' if ckpt else ''} -> {out}", flush=True)

    def eval_row(ep):
        nonlocal best, eval_time
        t0 = time.perf_counter()
        s, r = evaluate()
        eval_time += time.perf_counter() - t0
        rundir.append_row(log, writer, [ep, samples, f"{time.perf_counter() - t_start:.3f}",
                                        "", s, r, f"{eval_time:.3f}"])
        print(f"eval after epoch {ep}: success {s:.3f} return {r:.2f}", flush=True)
        save("policy", s)
        if best is None or s >= best:
            best = s
            save("best", s)
        checkpoint(ep + 1)
        return s

    stopping = rundir.stop_on_signals()
    epoch = first_epoch - 1
    evaluated = ckpt is not None

    def train_epoch(ep):
        """One pass over the data; evaluates every --eval-every epochs. Whether to stop (a
        signal, or --max-minutes)."""
        nonlocal samples, evaluated
        perm = torch.randperm(n)
        total = 0.0
        for s0 in range(0, n, args.batch_size):
            idx = perm[s0:s0 + args.batch_size]
            xi = x[idx]
            if args.obs_noise > 0:
                xi = xi + args.obs_noise * torch.randn(xi.shape) * keep
            loss = ((net(xi) - t[idx]) ** 2).mean()
            opt.zero_grad()
            loss.backward()
            opt.step()
            total += float(loss.detach()) * len(idx)
            samples += len(idx)
        wall = time.perf_counter() - t_start
        rundir.append_row(log, writer, [ep, samples, f"{wall:.3f}", f"{total / n:.6g}", "",
                                        "", f"{eval_time:.3f}"])
        evaluated = False
        if ep % args.eval_every == 0:
            eval_row(ep)
            evaluated = True
        return bool(stopping) or (args.max_minutes is not None and wall > 60 * args.max_minutes)

    stop = False
    for epoch in range(first_epoch, args.epochs + 1):
        if train_epoch(epoch):
            stop = True
            break
    while not stop and dagger_round < args.dagger_rounds:
        dagger_round += 1
        first_seed = args.dagger_seed + (dagger_round - 1) * args.dagger_episodes
        obs_new, labels_new, solved = collect_dagger(
            lambda: gym.make_vec(gid, num_envs=min(args.dagger_episodes, DAGGER_ENVS),
                                 num_threads=num_threads, **kw),
            act, first_seed, args.dagger_episodes, max_steps,
            args.dagger_beta ** dagger_round, np.random.default_rng([args.seed, dagger_round]))
        dagger_obs = np.concatenate([dagger_obs, obs_new])
        dagger_labels = np.concatenate([dagger_labels, labels_new])
        x, t = training_data()
        n = x.shape[0]
        print(f"DAgger round {dagger_round}: {len(obs_new)} states labelled on "
              f"{args.dagger_episodes} episodes (seeds {first_seed}..), {solved} solved; "
              f"{n} samples ({demo_steps} from the demos)", flush=True)
        for _ in range(args.dagger_epochs):
            epoch += 1
            if train_epoch(epoch):
                stop = True
                break
        if not evaluated:
            eval_row(epoch)
            evaluated = True
    if not evaluated:
        eval_row(epoch)
    log.close()
    print(f"best eval success {best:.3f}; policies: {os.path.join(out, 'policy.onnx')}, "
          f"{os.path.join(out, 'best.onnx')}")
    print(f"  mjskill eval --policy {os.path.join(out, 'best.onnx')} --episodes 100 "
          "--seed 10000")


if __name__ == "__main__":
    main()

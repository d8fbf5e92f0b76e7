"""PPO on any mjskill env and robot, on the CPU, with state observations and the native vector
env; saves the policy as an ONNX policy file (docs/training.md) that `mjskill eval --policy`,
`mjskill rollout --policy`, mjskill.policy.OnnxPolicy and examples/eval_in_maniskill.py run.

    pip install 'mjskill[train]'      # torch (any build; the CPU one is enough), onnx, mcap, h5py
    python examples/ppo.py --env-id PickCube-v1 --robot panda
    python examples/plot_training.py runs/<run>/log.csv

The algorithm is ManiSkill 3's state PPO baseline (examples/baselines/ppo/ppo.py): actor and
critic MLPs of 3x256 tanh units, a state-independent log std (init -0.5), gamma 0.8, GAE
lambda 0.9, a target KL of 0.1, partial resets (an env resets at success), and the value of
the final observation bootstrapped at every episode end. Its sizes come from a preset:
``--preset cpu`` (the default) was measured on a 2-core machine for the shortest time to 90 %
(128 envs x 50 steps, 4 epochs of 16 minibatches, native rollouts: PickCube-v1 at 90 % in
about 5 minutes);
``--preset maniskill`` is ManiSkill's examples.sh (1024 envs, 8 epochs of 32), sized for its
GPU simulation. docs/training.md lists each default, its source and the measurements, with
the one change to ManiSkill's settings in both presets: PokeCube-v1 in pd_ee_delta_pose.
Differences, all for the native env or the ONNX file:

* mjskill's vector env resets an ended env on the *next* step (gymnasium's next-step
  autoreset): that step's transition (action ignored, reward 0) is masked out of the update,
  and the final observation is the one returned with the end flag, so bootstrapping needs no
  ``final_observation``;
* observations are normalised by running statistics (clip 10), which the exported graph
  contains (--no-obs-norm for ManiSkill's raw observations);
* evaluation runs --num-eval-envs episodes on fixed seeds with the mean action; an episode
  ends at success (mjskill's env always resets at termination), so eval success is
  ManiSkill's ``success_once``;
* the actor does not see the gripper joints' velocities (``--gripper-qvel observe`` to show
  them): while a gripper pinches an object, PhysX reports a solver residual there (the Panda's
  fingers: 0.02-0.4 m/s, standing still), where mjskill reports the fingers' motion (about
  0), so a policy that reads them behaves differently in ManiSkill
  (docs/outcome-physics.md). The exported graph has zero weights on those inputs.

With ``--rollout native`` (the default) the vector env runs the T steps of an iteration in one
call, with the actor evaluated on its threads (``mjskill.GaussianMlp``: the same network in
f32, actions sampled from a per-env random stream), and the log-probs and values of the stored
observations come from one batched torch pass afterwards. ``--rollout torch`` is the
one-step-per-call loop with torch sampling: the default under ``--preset maniskill``, and the
only way with ``--simulator maniskill`` or ``--action-floor``, which take it by default.
``--ray-workers N`` steps the training envs on N Ray actors
(``mjskill.ray.RayVectorEnv``, on the local machine or the cluster of ``RAY_ADDRESS``) and
learns here; with the same seed and env count it learns the same weights as the local run.

``--simulator maniskill`` trains the same learner on the real ManiSkill 3's CPU simulation (one
PhysX env per slot in this process, about 100-400 steps/s per core), to compare the two
simulators' learning curves at equal steps; it needs mani_skill, not mjskill.

Logs ``log.csv`` in the run directory every iteration: iteration, env_steps, wall_time,
sim_time (seconds in the vector env's reset/step/rollout; native rollouts include the actor's
forward passes on the env threads), learner_time (infer + gae + update), train_success and
train_return (episodes that ended during the iteration); evaluations are rows of their own
(train columns empty) with eval_success and eval_return of the policy after env_steps steps;
then infer_time (the rollout's torch forward passes), gae_time (GAE and the observation
statistics), update_time and eval_time. ``--clock thread`` makes the time columns this
thread's CPU time, a measure of cost that other processes on a busy machine do not inflate
(with --num-threads 1 --torch-threads 1 all the work runs on this thread).
"""

from __future__ import annotations

import argparse
import os
import sys
import time

# torch's OpenMP threads spin for a while after each parallel region (GNU OpenMP's default),
# so between two forward passes of a torch rollout they keep the cores from the env threads:
# 256 envs on 2 env threads stepped at 15,000 env steps/s with them spinning, 18,300 with them
# asleep (docs/training.md). They sleep unless the caller chose otherwise; set before torch
# loads, which reads it once.
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

import gymnasium as gym
import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from demos import pretrain  # noqa: E402
from policy_onnx import atomic_write, parse_floors  # noqa: E402, F401 (atomic_write: tests)
from training import rundir  # noqa: E402
from training.args import (  # noqa: E402
    changed_options, command_line, finite_at_least_zero, non_negative, nonempty, number_in,
    option_names, positive, same_dir, with_values, without_option)
from training.evaluate import run_episodes  # noqa: E402
from training.export import metadata, save_policy  # noqa: E402
from training.rundir import (  # noqa: E402, F401 (RUN_LOCK: tests)
    RUN_LOCK, append_row, check_checkpoint_is_the_runs)

#: How this script names itself in the shared modules' messages.
SCRIPT = "examples/ppo.py"

#: The learning rate with --demos (measured, docs/training.md).
DEMO_LEARNING_RATE = 5e-5

#: --demo-logstd's range: a sampling std from 0.0009 to 2.7 (the action spaces' bounds are
#: about ±1). Outside it the Gaussian's log-probabilities overflow or underflow float32.
DEMO_LOGSTD_RANGE = (-7.0, 1.0)

#: ManiSkill's ppo.py defaults (its Args dataclass).
BASE = dict(
    num_envs=512,
    num_steps=50,
    total_timesteps=10_000_000,
    learning_rate=3e-4,
    gamma=0.8,
    gae_lambda=0.9,
    update_epochs=4,
    num_minibatches=32,
    target_kl=0.1,
    clip_coef=0.2,
    ent_coef=0.0,
    vf_coef=0.5,
    max_grad_norm=0.5,
    eval_freq=25,
    num_eval_envs=8,
    control_mode="pd_joint_delta_pos",
)

#: Per-task settings of ManiSkill's examples/baselines/ppo/examples.sh; the tasks it does not
#: list take PickCube-v1's (same robot, same 50-step horizon). One change, measured here
#: (docs/training.md): PokeCube-v1 trains in pd_ee_delta_pose, because in ManiSkill's
#: pd_joint_delta_pos no run here reached a single success in up to 5 M steps, while the
#: end-effector mode reaches 97 % in 2.3 M.
TASKS = {
    "PickCube-v1": dict(num_envs=1024, update_epochs=8, num_minibatches=32,
                        total_timesteps=10_000_000),
    "PokeCube-v1": dict(num_envs=1024, update_epochs=8, num_minibatches=32,
                        total_timesteps=5_000_000, eval_freq=10, num_steps=20,
                        control_mode="pd_ee_delta_pose"),
}


#: The presets: ``cpu`` (the default) is measured on the project's 2-core machine for the
#: shortest time to 90 % (docs/training.md, "Defaults that learn fast"); ``maniskill`` is
#: ManiSkill's settings above, sized for its GPU simulation (1024 envs per iteration), and
#: the default of every run before 29 November 2026.
PRESETS = ("cpu", "maniskill")

#: The cpu preset's changes to ManiSkill's settings: fewer envs per iteration, so the policy
#: updates 8 times as often per env step, half the epochs, minibatches of 400 samples, and
#: an evaluation every 64 k env steps (measured on PickCube-v1). PokeCube-v1 takes the
#: recipe of its shipped policy instead (256 envs x 20 steps, 8 epochs of 32, 100 eval envs
#: every 51 k env steps): with PickCube-v1's sizes it rose to 66 % and fell back to 6 %.
CPU = dict(num_envs=128, update_epochs=4, num_minibatches=16, eval_freq=10, num_eval_envs=32)
CPU_TASKS = {"PokeCube-v1": dict(num_envs=256, update_epochs=8, num_minibatches=32,
                                 eval_freq=10, num_eval_envs=100)}


def defaults(env_id: str, preset: str = "cpu") -> dict:
    """The option defaults of ``env_id`` under ``preset`` (one of PRESETS)."""
    d = {**BASE, **TASKS.get(env_id, TASKS["PickCube-v1"])}
    if preset == "cpu":
        d.update(CPU)
        d.update(CPU_TASKS.get(env_id, {}))
    return d


def parse_args(argv=None, check=True):
    pre = argparse.ArgumentParser(add_help=False)
    pre.add_argument("--env-id", default="PickCube-v1")
    pre.add_argument("--preset", choices=PRESETS, default="cpu")
    known = pre.parse_known_args(argv)[0]
    d = defaults(known.env_id, known.preset)
    p = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument("--env-id", default="PickCube-v1", help="mjskill env id")
    p.add_argument("--preset", choices=PRESETS, default="cpu",
                   help="the defaults of the options below: cpu (measured for the shortest "
                        "time to success on a CPU: 128 envs, 4 epochs of 16 minibatches) or "
                        "maniskill (ManiSkill's examples.sh, sized for 1024 GPU envs; the "
                        "default before 29 November 2026)")
    p.add_argument("--robot", default=None, help="robot uid (default: the env's)")
    p.add_argument("--control-mode", default=None,
                   help=f"control mode (default: the demos' with --demos, else "
                        f"{d['control_mode']})")
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--num-envs", type=positive, default=d["num_envs"])
    p.add_argument("--num-threads", type=positive, default=None,
                   help="threads of the native vector env (default: the machine's cores; "
                        "with --ray-workers N, the cluster's CPUs divided among the N actors)")
    p.add_argument("--torch-threads", type=positive, default=os.cpu_count() or 1)
    p.add_argument("--device", choices=("auto", "cpu", "cuda"), default="auto",
                   help="where the learner runs: the update and the rollout's torch forward "
                        "passes (auto: cuda when torch sees a GPU); the envs stay on the CPU")
    p.add_argument("--num-steps", type=positive, default=d["num_steps"],
                   help="rollout length per env and iteration")
    p.add_argument("--total-timesteps", type=positive, default=d["total_timesteps"])
    p.add_argument("--max-minutes", type=float, default=None,
                   help="stop after this much wall time (the policy is saved)")
    p.add_argument("--stop-at-success", type=float, default=None,
                   help="stop once an evaluation's success rate reaches this (e.g. 0.9)")
    p.add_argument("--learning-rate", type=float, default=None,
                   help=f"Adam's learning rate (default {d['learning_rate']}; with --demos "
                        f"{DEMO_LEARNING_RATE}: a cloned actor does not survive larger steps)")
    p.add_argument("--anneal-lr", action="store_true")
    p.add_argument("--gamma", type=float, default=d["gamma"])
    p.add_argument("--gae-lambda", type=float, default=d["gae_lambda"])
    p.add_argument("--finite-horizon-gae", action="store_true",
                   help="ManiSkill's finite-horizon GAE (its default: off)")
    p.add_argument("--update-epochs", type=positive, default=d["update_epochs"])
    p.add_argument("--num-minibatches", type=positive, default=d["num_minibatches"])
    p.add_argument("--target-kl", type=float, default=d["target_kl"])
    p.add_argument("--clip-coef", type=float, default=d["clip_coef"])
    p.add_argument("--ent-coef", type=float, default=d["ent_coef"])
    p.add_argument("--vf-coef", type=float, default=d["vf_coef"])
    p.add_argument("--max-grad-norm", type=float, default=d["max_grad_norm"])
    p.add_argument("--reward-scale", type=float, default=1.0)
    p.add_argument("--reward-mode", choices=("normalized_dense", "sparse"), default=None,
                   help="the env's reward: ManiSkill's normalised dense reward (the default), "
                        "or sparse, 1 at success (the default with --demos: the cloned actor "
                        "already succeeds, and the dense reward pays PPO for other things)")
    p.add_argument("--hidden", type=positive, nargs="+", default=[256, 256, 256])
    p.add_argument("--no-obs-norm", action="store_true")
    p.add_argument("--gripper-qvel", choices=("hide", "observe"), default="hide",
                   help="hide the gripper joints' velocities from the actor (default) or "
                        "observe them (ManiSkill's script)")
    p.add_argument("--eval-freq", type=positive, default=d["eval_freq"],
                   help="evaluate every N iterations (and at the first and last)")
    p.add_argument("--num-eval-envs", type=positive, default=d["num_eval_envs"])
    p.add_argument("--eval-seed", type=int, default=2**31,
                   help="seed of the first evaluation episode (the same seeds every time)")
    p.add_argument("--clock", choices=("wall", "thread"), default="wall",
                   help="what the log's time columns measure: wall time, or this thread's CPU "
                        "time (time.thread_time), which waiting for other processes does not "
                        "count: with --num-threads 1 --torch-threads 1 every computation runs "
                        "on this thread, so it measures the run's cost on a busy machine")
    p.add_argument("--out", type=nonempty, default=None,
                   help="run directory (default runs/<env>__<robot>__<seed>)")
    p.add_argument("--rollout", choices=["native", "torch"], default=None,
                   help="native: the actor runs inside the vector env's threads, T steps per "
                        "call, log-probs and values in one batched pass afterwards (the "
                        "default); torch: one env step and one torch forward per step (the "
                        "default with --preset maniskill, --simulator maniskill or "
                        "--action-floor, the only ways for the last two)")
    p.add_argument("--ray-workers", type=non_negative, default=0,
                   help="step the training envs on N Ray actors (mjskill.ray.RayVectorEnv, "
                        "--num-threads threads each; RAY_ADDRESS for a cluster) and learn "
                        "here; 0: local. Same seed and env count give the same weights")
    p.add_argument("--simulator", choices=["mjskill", "maniskill"], default="mjskill",
                   help="maniskill: train on the real ManiSkill 3's CPU simulation instead (needs "
                        "mani_skill; one PhysX env per vector slot, stepped in this process) to "
                        "compare the two simulators under the same learner")
    p.add_argument("--action-floor", metavar="INDEX:LEAST", action="append", default=[],
                   help="a least value for an action component, in training, evaluation and "
                        "the exported file (repeatable; e.g. 7:-0.545 keeps the WidowX AI's "
                        "carriage target at 10 mm or more, docs/training.md); torch rollouts")
    p.add_argument("--demos", metavar="FILE", nargs="+", default=None,
                   help="demonstrations to learn from (mjskill rollout recordings, .mcap, or "
                        "ManiSkill trajectory files, .h5 with their .json): the actor is "
                        "cloned from them and the critic fitted to their returns before PPO "
                        "starts, and a behaviour-cloning term that decays to 0 over "
                        "--bc-decay-steps joins PPO's loss (docs/training.md, 'Learning from "
                        "demonstrations'); only successful episodes are used")
    p.add_argument("--bc-epochs", type=positive, default=200,
                   help="passes over the demos of the warm start (actor and critic)")
    p.add_argument("--bc-obs-noise", type=finite_at_least_zero, default=0.1,
                   help="std of the Gaussian noise added to the (normalised) observations of "
                        "the behaviour cloning")
    p.add_argument("--bc-coef", type=float, default=0.5,
                   help="weight of the behaviour-cloning term in PPO's loss at the start")
    p.add_argument("--bc-decay-steps", type=positive, default=500_000,
                   help="env steps over which the behaviour-cloning term falls linearly to 0")
    p.add_argument("--critic-warmup-steps", type=non_negative, default=100_000,
                   help="with --demos: env steps at the start during which only the critic "
                        "learns (the cloned actor is held while the critic learns its returns)")
    p.add_argument("--lr-warmup-steps", type=non_negative, default=200_000,
                   help="with --demos: env steps (after the critic's warm-up) over which the "
                        "learning rate rises linearly from 0: Adam's first steps move every "
                        "weight by about the learning rate, which a cloned actor does not "
                        "survive")
    p.add_argument("--demo-logstd", type=number_in(
                       *DEMO_LOGSTD_RANGE, " (a sampling std from 0.0009 to 2.7)"), default=-2.5,
                   help="the sampling log std after the warm start, -7 to 1 (PPO's own start "
                        "is -0.5; a narrower one keeps the cloned behaviour while PPO begins)")
    p.add_argument("--resume", metavar="RUN_DIR", default=None,
                   help="continue the run in RUN_DIR from its last checkpoint (checkpoint.pt: "
                        "weights, optimiser, observation statistics, step count, random state) "
                        "with its saved options; options given here override them, except "
                        f"those that define the run ({', '.join(RUN_DEFINING)})")
    args = p.parse_args(argv)
    # Defaults that depend on --demos (docs/training.md, 'Learning from demonstrations').
    if args.learning_rate is None:
        args.learning_rate = DEMO_LEARNING_RATE if args.demos else d["learning_rate"]
    if args.reward_mode is None:
        args.reward_mode = "sparse" if args.demos else "normalized_dense"
    if check and args.resume is None:
        check_args(p, args)
    elif check and not os.path.isfile(os.path.join(args.resume, "checkpoint.pt")):
        p.error(f"--resume {args.resume}: no checkpoint.pt there (a run writes one at every "
                "evaluation and when it stops)")
    elif check and args.out is not None and not same_dir(args.out, args.resume):
        p.error(f"--out {args.out} with --resume {args.resume}: a resumed run continues in its "
                "own directory; leave --out out (or copy the run directory and resume the copy)")
    return args


#: Options a resumed run cannot change: they define the networks, the data or the envs.
RUN_DEFINING = ("env_id", "preset", "robot", "control_mode", "seed", "num_envs", "num_steps", "hidden",
                "no_obs_norm", "gripper_qvel", "rollout", "simulator", "ray_workers",
                "action_floor", "demos", "bc_epochs", "bc_obs_noise", "demo_logstd",
                "reward_mode")


def check_args(p, args):
    """Refuses settings that cannot train (argparse errors: usage and exit status 2)."""
    batch = args.num_envs * args.num_steps
    if batch // args.num_minibatches < 2:
        p.error(f"--num-minibatches {args.num_minibatches} leaves minibatches of fewer than 2 "
                f"samples (the batch is --num-envs x --num-steps = {batch}), which the update "
                f"skips, so nothing would train; at most {batch // 2}")
    if args.total_timesteps < batch:
        p.error(f"--total-timesteps {args.total_timesteps} is less than one iteration "
                f"(--num-envs x --num-steps = {batch})")
    for name in ("learning_rate", "gamma", "gae_lambda", "clip_coef", "vf_coef",
                 "max_grad_norm", "reward_scale", "target_kl", "ent_coef", "bc_coef"):
        v = getattr(args, name)
        if not np.isfinite(v) or v < 0:
            p.error(f"--{name.replace('_', '-')} {v} must be a finite number >= 0")
    try:
        parse_floors(args.action_floor)  # examples/policy_onnx.py floor's rule
    except ValueError as e:
        p.error(f"--action-floor {e}")
    if args.action_floor and (args.rollout == "native" or args.ray_workers):
        p.error("--action-floor works with torch rollouts (--rollout torch)")
    if args.demos and args.simulator != "mjskill":
        p.error("--demos trains on mjskill (--simulator mjskill)")
    if args.learning_rate == 0:
        p.error("--learning-rate 0 trains nothing")
    if args.gamma > 1 or args.gae_lambda > 1:
        p.error("--gamma and --gae-lambda must be at most 1")
    if args.max_minutes is not None and not args.max_minutes > 0:
        p.error(f"--max-minutes {args.max_minutes} must be > 0")
    if args.out is not None and os.path.exists(args.out) and not os.path.isdir(args.out):
        p.error(f"--out {args.out} exists and is not a directory; the run directory holds "
                "policy.onnx, best.onnx, checkpoints and log.csv")


def maniskill_vec_env(env_id, num_envs, robot, control_mode, reward_mode="normalized_dense"):
    """ManiSkill's CPU envs (`sim_backend="physx_cpu"`, one per slot) as a gymnasium
    SyncVectorEnv with next-step autoreset and env i seeded s + i: the conventions of mjskill's
    native vector env, so the learner below runs unchanged on either simulator."""
    import mani_skill.envs  # noqa: F401  (registers ManiSkill's envs)
    from mani_skill.utils.wrappers.gymnasium import CPUGymWrapper

    kw = dict(num_envs=1, obs_mode="state", control_mode=control_mode,
              reward_mode=reward_mode, sim_backend="physx_cpu", render_backend="none")
    if robot is not None:
        kw["robot_uids"] = robot

    def thunk():
        return CPUGymWrapper(gym.make(env_id, **kw))

    envs = gym.vector.SyncVectorEnv([thunk] * num_envs,
                                    autoreset_mode=gym.vector.AutoresetMode.NEXT_STEP)
    base = envs.envs[0].unwrapped
    envs.robot_uids = base.robot_uids if isinstance(base.robot_uids, str) else base.robot_uids[0]
    envs.control_mode = base.control_mode
    envs.max_episode_steps = envs.envs[0].spec.max_episode_steps or 50
    # The gripper joints' velocities in ManiSkill's state observation (qpos, then qvel, of the
    # active joints first), as mjskill's `gripper_qvel_obs`.
    active = [j.name for j in base.agent.robot.get_active_joints()]
    grip = {j.name for key, c in base.agent.controller.controllers.items() if "gripper" in key
            for j in c.joints}
    envs.gripper_qvel_obs = [len(active) + i for i, n in enumerate(active) if n in grip]
    return envs


#: The least variance of an observation entry in statistics taken from demos (std 0.01).
DEMO_VAR_FLOOR = 1e-4


class RunningMeanStd:
    """Running mean and variance (parallel algorithm), float64."""

    def __init__(self, dim):
        self.mean = np.zeros(dim)
        self.var = np.ones(dim)
        self.count = 1e-4

    def update(self, x):
        m, v, n = x.mean(0), x.var(0), x.shape[0]
        delta, total = m - self.mean, self.count + n
        self.mean = self.mean + delta * n / total
        self.var = (self.var * self.count + v * n + delta**2 * self.count * n / total) / total
        self.count = total

    def std(self):
        return np.sqrt(self.var + 1e-8)


def resumed_args(argv):
    """The options of a resumed run: the saved run's, then those given now. Returns (args,
    checkpoint)."""
    given = parse_args(argv)
    ckpt = load_checkpoint(given.resume)
    saved_argv = list(ckpt["argv"])
    if "--preset" not in option_names(saved_argv):
        # Saved before --preset existed: the run took ManiSkill's settings.
        saved_argv = ["--preset", "maniskill"] + saved_argv
    # The options given now, without --resume DIR (or --resume=DIR).
    rest = without_option(list(sys.argv[1:] if argv is None else argv), "--resume")
    if "--action-floor" in option_names(rest):
        # Given again, the floors replace the saved ones (then compared with them below).
        saved_argv = without_option(saved_argv, "--action-floor")
        saved_floors = parse_args(list(ckpt["argv"]), check=False).action_floor
    else:
        saved_floors = None
    args = parse_args(saved_argv + rest, check=False)
    args.resume = None
    parse_args(saved_argv + rest)  # the merged options must be valid (exits if not)
    saved = parse_args(saved_argv, check=False)
    if saved_floors is not None:
        saved.action_floor = saved_floors

    def differs(k, a, b):
        if k == "action_floor":  # the same floors, in any order or spelling
            return parse_floors(a) != parse_floors(b)
        if k == "demos" and a and b:  # the same files, relative or absolute
            return [os.path.abspath(x) for x in a] != [os.path.abspath(x) for x in b]
        return a != b

    changed = changed_options(args, saved, RUN_DEFINING, differs)
    if changed:
        sys.exit(f"error: --resume {given.resume}: {', '.join(changed)} "
                 "cannot change when a run continues (they define its networks, data or envs)")
    args.resume = given.resume
    args.out = given.resume  # a resumed run continues in its own directory
    return args, ckpt


def hold_run_dir(out):
    """rundir.hold_run_dir for this script: one writer per run directory."""
    return rundir.hold_run_dir(out, SCRIPT)


#: What a checkpoint of this script holds.
CHECKPOINT_KEYS = ("actor", "critic", "logstd", "optimizer", "obs_mean", "obs_var",
                   "obs_count", "argv", "command", "iteration", "global_step", "best",
                   "resumes", "times", "torch_rng", "cuda_rng")


def load_checkpoint(run):
    """The checkpoint of run directory ``run``; exits with an error naming the file when it
    cannot be read (damaged, cut short, not this script's)."""
    return rundir.load_checkpoint(run, CHECKPOINT_KEYS, SCRIPT)


#: log.csv's columns.
LOG_HEADER = ["iteration", "env_steps", "wall_time", "sim_time", "learner_time",
              "train_success", "train_return", "eval_success", "eval_return",
              "infer_time", "gae_time", "update_time", "eval_time"]


def start_log(log_path, resume_at=None):
    """rundir.start_log with this script's columns: a new log, or a resumed run's (``resume_at``:
    the (iteration, env steps) its checkpoint continues from) with the rows after the
    checkpoint dropped."""
    return rundir.start_log(log_path, LOG_HEADER, resume_at, "ppo.py")


def default_rollout(args):
    """--rollout when not given: native with --ray-workers and under the cpu preset (measured:
    as reliable as torch rollouts, docs/training.md), torch where native cannot run
    (--simulator maniskill, --action-floor) and under the maniskill preset (the loop of every
    run before the cpu preset)."""
    if args.ray_workers:
        return "native"
    if args.simulator == "maniskill" or args.action_floor or args.preset == "maniskill":
        return "torch"
    return "native"


def default_num_threads(args):
    """--num-threads when not given: the machine's cores, or with --ray-workers N the
    cluster's CPUs shared among the N actors (each reserves that many)."""
    if not args.ray_workers:
        return os.cpu_count() or 1
    import ray

    if not ray.is_initialized():
        ray.init()
    cpus = int(ray.cluster_resources().get("CPU", 0))
    if cpus < args.ray_workers:
        sys.exit(f"error: --ray-workers {args.ray_workers} needs at least {args.ray_workers} CPUs "
                 f"(one per actor), but the Ray cluster has {cpus}")
    return max(1, cpus // args.ray_workers)


def main(argv=None):
    args = parse_args(argv)
    ckpt = None
    # One writer per run directory: its lock is taken as soon as the directory is known.
    run_lock = hold_run_dir(args.resume or args.out) if (args.resume or args.out) else None
    if args.resume is not None:
        args, ckpt = resumed_args(argv)
    demos = None
    demo_files = None
    if args.demos:
        # Every file is read and checked before the run's envs are built (one env is made
        # for the spaces the demos must fit).
        from demos import DemoError, check_unchanged, fingerprints, load, mjskill_spaces

        try:
            if ckpt is not None and ckpt.get("demo_files"):
                # The files the run started with, unchanged (a checkpoint written before
                # fingerprints were kept has none: its files are taken as they are).
                check_unchanged(ckpt["demo_files"], args.resume)
            demos = load(args.demos, args.env_id, args.robot, args.control_mode,
                         spaces=mjskill_spaces if args.simulator == "mjskill" else None)
            demo_files = fingerprints(args.demos)
        except DemoError as e:
            sys.exit(f"error: {e}")
        for note in demos.notes:
            print(f"note: {note}", flush=True)
        args.robot = args.robot or demos.robot
        args.control_mode = args.control_mode or demos.control_mode
    if args.control_mode is None:
        args.control_mode = defaults(args.env_id)["control_mode"]
    clock = time.perf_counter if args.clock == "wall" else time.thread_time
    import torch
    import torch.nn as nn
    from torch.distributions.normal import Normal

    if args.device == "auto":
        args.device = "cuda" if torch.cuda.is_available() else "cpu"
    if args.device == "cuda":
        if not torch.cuda.is_available():
            sys.exit("error: --device cuda, but torch sees no CUDA device (torch "
                     f"{torch.__version__}, cuda build {torch.version.cuda}); use --device cpu")
        # cuBLAS is deterministic with a fixed workspace (must be set before its first use).
        os.environ.setdefault("CUBLAS_WORKSPACE_CONFIG", ":4096:8")
        torch.use_deterministic_algorithms(True)
    dev = torch.device(args.device)
    torch.manual_seed(args.seed)
    np.random.seed(args.seed)
    torch.set_num_threads(args.torch_threads)
    if args.num_threads is None:
        args.num_threads = default_num_threads(args)
    if args.rollout is None:
        args.rollout = default_rollout(args)
    native = args.rollout == "native"
    if args.simulator == "maniskill" and (native or args.ray_workers):
        sys.exit("--simulator maniskill steps one env per slot: use --rollout torch, no --ray-workers")
    if args.ray_workers and not native:
        sys.exit("--ray-workers runs native rollouts: leave --rollout at native")
    if args.simulator == "maniskill":
        envs = maniskill_vec_env(args.env_id, args.num_envs, args.robot, args.control_mode,
                                 args.reward_mode)
        eval_envs = maniskill_vec_env(args.env_id, args.num_eval_envs, args.robot,
                                      args.control_mode, args.reward_mode)
        robot, mode, max_steps = envs.robot_uids, envs.control_mode, envs.max_episode_steps
        version = ""
    else:
        import mjskill  # noqa: F401  (registers the envs)

        gid = f"mjskill/{args.env_id}"
        kw = dict(robot_uids=args.robot, control_mode=args.control_mode, obs_mode="state",
                  reward_mode=args.reward_mode)
        # As ManiSkill's ppo.py (eval_reconfiguration_freq=1): each evaluation episode is its
        # seed's, PegInsertionSide-v1's shapes included.
        def make_eval_envs():
            return gym.make_vec(gid, num_envs=args.num_eval_envs, num_threads=args.num_threads,
                                reconfiguration_freq=1, **kw)

        eval_envs = make_eval_envs()
        if demos is not None:
            from demos import DemoError, replay_missing_obs

            try:
                replay_missing_obs(demos, lambda: gym.make(gid, **kw))
            except DemoError as e:
                sys.exit(f"error: {e}")
            dim = eval_envs.single_observation_space.shape[0]
            if demos.obs_dim != dim:
                sys.exit(f"error: --demos {' '.join(args.demos)}: observations of "
                         f"{demos.obs_dim} values, but {args.env_id} with {args.robot} in "
                         f"{args.control_mode} observes {dim} (demos of another mjskill "
                         "version or env options?)")
            print(f"demos: {len(demos.episodes)} successful episodes, {demos.steps} steps "
                  f"from {len(demos.files)} file(s); {demos.skipped_failed} failed episodes "
                  "left out", flush=True)
        if args.ray_workers:
            from mjskill.ray import RayVectorEnv

            envs = RayVectorEnv(args.env_id, args.num_envs, args.ray_workers,
                                num_threads=args.num_threads, **kw)
        else:
            envs = gym.make_vec(gid, num_envs=args.num_envs, num_threads=args.num_threads, **kw)
        base = eval_envs.unwrapped
        robot, mode, max_steps = base.robot_uids, base.control_mode, base.max_episode_steps
        version = mjskill.__version__
    sim_tag = "" if args.simulator == "mjskill" else f"__{args.simulator}"
    out = args.out or os.path.join("runs",
                                   f"{args.env_id}__{robot}__{mode}__{args.seed}{sim_tag}")
    if run_lock is None:
        run_lock = hold_run_dir(out)
    obs_dim = envs.single_observation_space.shape[0]
    act_dim = envs.single_action_space.shape[0]
    low = torch.as_tensor(envs.single_action_space.low).to(dev)
    high = torch.as_tensor(envs.single_action_space.high).to(dev)
    floors = parse_floors(args.action_floor)
    if any(not 0 <= k < len(low) for k in floors):
        # Known only now (the action size is the env's); a usage error as argparse's.
        print(f"{os.path.basename(sys.argv[0])}: error: --action-floor indices "
              f"{sorted(floors)} out of range 0..{len(low) - 1} ({robot} in {mode} has "
              f"{len(low)} action components)", file=sys.stderr)
        sys.exit(2)
    for k, v in floors.items():
        low[k] = max(float(low[k]), v)
    # The command that trained the run (for a resumed run: the first one, whose options it
    # keeps) and the options it was parsed from.
    run_argv = list(ckpt["argv"]) if ckpt is not None else list(
        sys.argv[1:] if argv is None else argv)
    for name, value in (("--preset", args.preset), ("--rollout", args.rollout)):
        if name not in option_names(run_argv):
            # Recorded, so that the command and a resume keep today's defaults.
            run_argv += [name, value]
    # The policy files' training_command is the command as typed (relative demo paths
    # included); the checkpoint's argv, which --resume runs again, names the demos by
    # absolute path.
    command = ckpt["command"] if ckpt is not None else command_line(run_argv)
    if ckpt is None and args.demos:
        # The demo files by absolute path: a resume from another directory finds them.
        run_argv = with_values(run_argv, "--demos", [os.path.abspath(f) for f in args.demos])
    if ckpt is not None:
        check_checkpoint_is_the_runs(out, command, robot, mode)

    def mlp(n_out, last_std, orthogonal=True):
        """tanh MLP; PPO's orthogonal initialisation (gain sqrt 2, the last layer
        ``last_std``), or torch's default one (``orthogonal=False``), which behaviour cloning
        generalises from far better (docs/training.md, 'Learning from demonstrations')."""
        layers, n_in = [], obs_dim
        for h in args.hidden:
            lin = nn.Linear(n_in, h)
            if orthogonal:
                nn.init.orthogonal_(lin.weight, np.sqrt(2))
                nn.init.constant_(lin.bias, 0.0)
            layers += [lin, nn.Tanh()]
            n_in = h
        lin = nn.Linear(n_in, n_out)
        if orthogonal:
            nn.init.orthogonal_(lin.weight, last_std)
            nn.init.constant_(lin.bias, 0.0)
        return nn.Sequential(*layers, lin)

    # The actor's inputs: the normalised observation with the hidden entries zeroed.
    grip = envs.gripper_qvel_obs if args.simulator == "maniskill" else base.gripper_qvel_obs
    hidden = list(grip) if args.gripper_qvel == "hide" else []
    actor_keep = torch.ones(obs_dim)
    actor_keep[hidden] = 0.0
    actor_keep = actor_keep.to(dev)

    class Hide(nn.Module):
        def forward(self, x):
            return x * actor_keep

    # Initialised on the CPU (the same weights for every device), then moved.
    actor = nn.Sequential(Hide(), *mlp(act_dim, 0.01 * np.sqrt(2),
                                       orthogonal=demos is None)).to(dev)
    critic = mlp(1, 1.0).to(dev)
    logstd = nn.Parameter(torch.full((1, act_dim), -0.5, device=dev))
    params = list(actor.parameters()) + list(critic.parameters()) + [logstd]
    opt = torch.optim.Adam(params, lr=args.learning_rate, eps=1e-5)
    rms = RunningMeanStd(obs_dim)

    def norm(o):
        """Observations (numpy, CPU) normalised, as float32 on the learner's device: one copy
        per call, whatever the number of envs."""
        if args.no_obs_norm:
            return torch.as_tensor(o, dtype=torch.float32).to(dev)
        x = (o - rms.mean) / rms.std()
        return torch.as_tensor(np.clip(x, -10.0, 10.0), dtype=torch.float32).to(dev)

    def policy_params():
        """The actor as mjskill.GaussianMlp's arguments: weights (inputs x outputs, the hidden
        inputs' rows zeroed, as the actor multiplies them by zero), observation statistics,
        the sampling std and the noise seed."""
        layers = [(m.weight.detach().cpu().numpy().T.copy(),
                   m.bias.detach().cpu().numpy().copy())
                  for m in actor if isinstance(m, nn.Linear)]
        layers[0][0][hidden] = 0.0
        mean = np.zeros(obs_dim) if args.no_obs_norm else rms.mean
        std = np.ones(obs_dim) if args.no_obs_norm else rms.std()
        return dict(layers=layers, obs_mean=np.asarray(mean, np.float64),
                    obs_std=np.asarray(std, np.float64),
                    obs_clip=None if args.no_obs_norm else 10.0,
                    std=logstd.detach().exp().cpu().numpy().reshape(-1).copy(), seed=args.seed)

    def save(tag, eval_success):
        p = policy_params()
        extra = {}
        if demos is not None:
            extra["demos"] = (f"{len(demos.episodes)} episodes, {demos.steps} steps: "
                              + " ".join(os.path.basename(f) for f in demos.files))
            if demos.commands:
                # The `mjskill rollout` commands that recorded them, as examples/imitate.py
                # records its demos'.
                extra["demos_command"] = " ; ".join(demos.commands)
        if args.simulator != "mjskill":
            extra["simulator"] = args.simulator
        meta = metadata(
            args.env_id, robot, mode, command,
            "ppo (examples/ppo.py)" if demos is None else
            "ppo with a behaviour-cloning warm start and term (examples/ppo.py --demos)",
            global_step, eval_success, version, hidden, resumes, resume_commands, **extra)
        path = save_policy(out, tag, p["layers"], p["obs_mean"], p["obs_std"], meta,
                           obs_clip=None if args.no_obs_norm else 10.0, floors=floors,
                           floor_note="trained with --action-floor " + " ".join(args.action_floor))
        rundir.save_torch(os.path.join(out, f"{tag}.pt"), weights())
        return path

    def weights():
        """The networks and observation statistics (CPU tensors: loads with
        ``torch.load(path, weights_only=True)``)."""
        return {"actor": {k: v.cpu() for k, v in actor.state_dict().items()},
                "critic": {k: v.cpu() for k, v in critic.state_dict().items()},
                "logstd": logstd.detach().cpu(), "obs_mean": torch.from_numpy(rms.mean),
                "obs_var": torch.from_numpy(rms.var), "obs_count": float(rms.count)}

    def checkpoint(next_iteration):
        """Everything --resume needs to continue from the start of ``next_iteration``."""
        state = weights()
        state.update(
            optimizer=opt.state_dict(), argv=run_argv, command=command, iteration=next_iteration,
            demo_files=demo_files,
            global_step=global_step, best=best, resumes=resumes,
            resume_commands=resume_commands,
            times=dict(wall=clock() - t_start, sim=sim_time, infer=infer_time, gae=gae_time,
                       update=update_time, eval=eval_time),
            torch_rng=torch.get_rng_state(),
            cuda_rng=torch.cuda.get_rng_state() if dev.type == "cuda" else None,
        )
        rundir.save_torch(os.path.join(out, "checkpoint.pt"), state)

    def evaluate():
        """One episode per eval env on fixed seeds, mean actions; (success rate, mean return).
        mjskill's eval envs are made afresh after every evaluation: the first observation after
        a reset carries the last step's finger contacts (`is_grasped`, as in ManiSkill), so
        reused envs would carry one evaluation's end into the next, and the same actor would
        score differently."""
        nonlocal eval_envs

        def act(obs):
            with torch.no_grad():
                return torch.clamp(actor(norm(obs)), low, high).cpu().numpy()

        result = run_episodes(eval_envs, act, args.eval_seed, max_steps)
        if args.simulator == "mjskill":
            eval_envs.close()
            eval_envs = make_eval_envs()
        return result

    if demos is not None:
        # The demos' steps: raw observations (normalised with the running statistics where
        # used), actions and discounted returns.
        demo_obs, demo_all_obs = demos.obs, demos.all_obs
        # (The expert's own labels where the demos carry them: noise-injected demos.)
        demo_act = torch.as_tensor(demos.labels).to(dev)
        demo_ret = torch.as_tensor(demos.returns(args.gamma, args.reward_mode)
                                   * args.reward_scale).to(dev)
        if ckpt is None:
            # The warm start: observation statistics from the demos, the actor's mean cloned,
            # the critic fitted to the returns, the sampling std narrowed.
            t0 = clock()
            if not args.no_obs_norm:
                rms.update(demo_obs.astype(np.float64))
                # A floor under the demos' spread (std 0.01): an entry the demos never vary
                # (Fetch's head joints, a velocity of 0) would otherwise turn the smallest
                # deviation into a clipped ±10 input.
                rms.var = np.maximum(rms.var, DEMO_VAR_FLOOR)
            pretrain(actor, critic, norm(demo_obs), demo_act, norm(demo_all_obs), demo_ret,
                     args.bc_epochs, seed=args.seed, obs_noise=args.bc_obs_noise,
                     log=lambda m: print(m, flush=True))
            with torch.no_grad():
                logstd.fill_(args.demo_logstd)
            print(f"warm start: {clock() - t0:.1f} s", flush=True)

    def bc_weight(step):
        """The behaviour-cloning term's weight after ``step`` env steps."""
        if demos is None:
            return 0.0
        return args.bc_coef * max(0.0, 1.0 - step / args.bc_decay_steps)

    T, N = args.num_steps, args.num_envs
    batch = T * N
    minibatch = batch // args.num_minibatches
    iterations = max(1, args.total_timesteps // batch)
    b_obs = np.zeros((T, N, obs_dim), np.float32)
    # The rollout's tensors live on the learner's device (observations stay numpy: the
    # statistics and the native buffers are numpy).
    b_act = torch.zeros((T, N, act_dim), device=dev)
    b_logp = torch.zeros((T, N), device=dev)
    b_rew = torch.zeros((T, N), device=dev)
    b_val = torch.zeros((T, N), device=dev)
    b_done = torch.zeros((T, N), device=dev)  # the episode ended at this step
    b_valid = torch.zeros((T, N), device=dev)  # this step was not an autoreset step

    log_path = os.path.join(out, "log.csv")
    # Seconds in: the vector env (sim_time; native rollouts include the actor's forward
    # passes on the env threads), the rollout's torch forward passes (infer_time), GAE and the
    # observation statistics (gae_time), the update (update_time), evaluations (eval_time).
    sim_time = infer_time = gae_time = update_time = eval_time = 0.0
    global_step = 0
    first_it = 1
    best = None
    resumes = []
    resume_commands = []
    if ckpt is not None:
        # Continue where the checkpoint was taken: the start of iteration `first_it`, right
        # after its evaluation. The log keeps the rows up to that point.
        actor.load_state_dict(ckpt["actor"])
        critic.load_state_dict(ckpt["critic"])
        with torch.no_grad():
            logstd.copy_(ckpt["logstd"])
        opt.load_state_dict(ckpt["optimizer"])
        rms.mean, rms.var = ckpt["obs_mean"].numpy().copy(), ckpt["obs_var"].numpy().copy()
        rms.count = float(ckpt["obs_count"])
        first_it, global_step, best = int(ckpt["iteration"]), int(ckpt["global_step"]), ckpt["best"]
        resumes = list(ckpt["resumes"]) + [global_step]
        resume_commands = list(ckpt.get("resume_commands", [])) + [
            command_line()]
        tm = ckpt["times"]
        sim_time, infer_time, gae_time = tm["sim"], tm["infer"], tm["gae"]
        update_time, eval_time = tm["update"], tm["eval"]
        torch.set_rng_state(ckpt["torch_rng"])
        if ckpt["cuda_rng"] is not None and dev.type == "cuda":
            torch.cuda.set_rng_state(ckpt["cuda_rng"])
        log, writer = start_log(log_path, (first_it, global_step))
        t_start = clock() - tm["wall"]
    else:
        log, writer = start_log(log_path)
        t_start = clock()
    print(f"{args.env_id} {robot} {mode}: obs {obs_dim}, act {act_dim}; {N} envs x {T} steps, "
          f"{iterations} iterations, {'native' if native else 'torch'} rollouts"
          f"{f' on {args.ray_workers} Ray workers' if args.ray_workers else ''}, "
          f"learner on {dev}"
          f"{f', resumed at iteration {first_it} ({global_step} steps)' if ckpt else ''} -> {out}",
          flush=True)

    t0 = clock()
    # A resumed run starts its envs afresh, from a seed of its own (the episodes in progress
    # when the run stopped are not continued).
    reset_seed = args.seed if ckpt is None else args.seed + 1_000_003 * len(resumes)
    if args.ray_workers:
        next_obs = envs.reset(seed=reset_seed)
    else:
        next_obs, _ = envs.reset(seed=reset_seed)
    sim_time += clock() - t0
    if native:
        buf = envs.rollout_buffers(T)
        if args.ray_workers:
            collect = envs.rollout
        else:
            from mjskill import GaussianMlp

            def collect(params, first_step, buffers):
                return envs.rollout(GaussianMlp(**params), first_step, buffers)
    prev_done = np.zeros(N, bool)
    ep_ret = np.zeros(N)
    # SIGINT or SIGTERM ends the run after the current iteration, with the final evaluation
    # and saves; a second one stops at once.
    stopping = rundir.stop_on_signals()
    it = next_it = first_it
    for it in range(first_it, iterations + 1):
        if (it % args.eval_freq == 1 or args.eval_freq == 1) and not (ckpt and it == first_it):
            t0 = clock()
            eval_s, eval_r = evaluate()
            eval_time += clock() - t0
            # An evaluation row: the policy after `global_step` env steps (on disk before
            # the checkpoint that counts it).
            append_row(log, writer, [
                it - 1, global_step, f"{clock() - t_start:.3f}", f"{sim_time:.3f}",
                f"{infer_time + gae_time + update_time:.3f}", "", "", eval_s, eval_r,
                f"{infer_time:.3f}", f"{gae_time:.3f}", f"{update_time:.3f}",
                f"{eval_time:.3f}"])
            print(f"eval after {global_step} steps: success {eval_s:.3f} return {eval_r:.2f}",
                  flush=True)
            save("policy", eval_s)
            if best is None or eval_s >= best:
                best = eval_s
                save("best", eval_s)
            checkpoint(it)
            if args.stop_at_success is not None and eval_s >= args.stop_at_success:
                print(f"eval success {eval_s:.3f} reached --stop-at-success "
                      f"{args.stop_at_success}", flush=True)
                next_it = it
                break
        if args.anneal_lr:
            opt.param_groups[0]["lr"] = (1.0 - (it - 1.0) / iterations) * args.learning_rate
        if demos is not None and args.lr_warmup_steps:
            ramp = (global_step - args.critic_warmup_steps) / args.lr_warmup_steps
            opt.param_groups[0]["lr"] = args.learning_rate * min(1.0, max(ramp, 0.05))
        # -- rollout ------------------------------------------------------------------------
        if native:
            # T steps in one call, the actor evaluated on the env threads; the log-probs and
            # values of the same observations in one batched pass (with the statistics the
            # rollout normalised by).
            t0 = clock()
            next_obs = collect(policy_params(), (it - 1) * T, buf)
            t1 = clock()
            with torch.no_grad():
                x = norm(buf["obs"].reshape(-1, obs_dim))
                mean = actor(x)
                dist = Normal(mean, logstd.exp().expand_as(mean))
                b_act = torch.as_tensor(buf["actions"]).reshape(T, N, act_dim).to(dev, copy=True)
                b_logp = dist.log_prob(b_act.reshape(-1, act_dim)).sum(1).view(T, N)
                b_val = critic(x).view(T, N)
            b_obs = buf["obs"]
            sim_time += t1 - t0
            infer_time += clock() - t1
            valid = ~buf["autoreset"]
            done = (buf["terminated"] | buf["truncated"]) & valid
            n_rew = buf["rewards"] * args.reward_scale
            n_done, n_valid = done, valid
            ended_success, ended_return = [], []
            for t in range(T):
                ep_ret += np.where(valid[t], buf["rewards"][t], 0.0)
                for i in np.flatnonzero(done[t]):
                    ended_success.append(bool(buf["terminated"][t, i]))
                    ended_return.append(ep_ret[i])
                    ep_ret[i] = 0.0
            global_step += T * N
        else:
            ended_success, ended_return = [], []
            n_rew = np.zeros((T, N))
            n_done = np.zeros((T, N), bool)
            n_valid = np.zeros((T, N), bool)
            for t in range(T):
                t0 = clock()
                b_obs[t] = next_obs
                with torch.no_grad():
                    x = norm(next_obs)
                    mean = actor(x)
                    dist = Normal(mean, logstd.exp().expand_as(mean))
                    a = dist.sample()
                    b_logp[t] = dist.log_prob(a).sum(1)
                    b_val[t] = critic(x).view(-1)
                b_act[t] = a
                act = torch.clamp(a, low, high).cpu().numpy()
                t1 = clock()
                next_obs, r, term, trunc, _ = envs.step(act)
                t2 = clock()
                sim_time += t2 - t1
                infer_time += t1 - t0
                valid = ~prev_done  # an env that ended on the last step resets now
                done = (term | trunc) & valid
                n_rew[t] = r * args.reward_scale
                n_done[t] = done
                n_valid[t] = valid
                ep_ret += np.where(valid, r, 0.0)
                for i in np.flatnonzero(done):
                    ended_success.append(bool(term[i]))
                    ended_return.append(ep_ret[i])
                    ep_ret[i] = 0.0
                prev_done = done
                global_step += N
        t0 = clock()
        # The rollout's rewards and flags to the learner's device: one copy each per rollout.
        b_rew = torch.as_tensor(n_rew, dtype=torch.float32).to(dev)
        b_done = torch.as_tensor(n_done, dtype=torch.float32).to(dev)
        b_valid = torch.as_tensor(n_valid, dtype=torch.float32).to(dev)
        if not args.no_obs_norm and demos is None:
            # (With --demos the statistics stay the demos': the cloned actor reads its inputs
            # as it learned them.)
            rms.update(b_obs.reshape(-1, obs_dim)[n_valid.reshape(-1)])
        # -- GAE: the value after step t is V(obs[t+1]), the final observation at an end -----
        with torch.no_grad():
            next_value = critic(norm(next_obs)).view(-1)
            adv = torch.zeros((T, N), device=dev)
            last = torch.zeros(N, device=dev)
            lam_sum = rew_sum = val_sum = torch.zeros(N, device=dev)
            for t in reversed(range(T)):
                nv = next_value if t == T - 1 else b_val[t + 1]
                # Propagate from step t+1 only when the episode goes on and t+1 is a real step.
                cont = 1.0 - b_done[t]
                if args.finite_horizon_gae:
                    lam_sum, rew_sum, val_sum = lam_sum * cont, rew_sum * cont, val_sum * cont
                    lam_sum = 1 + args.gae_lambda * lam_sum
                    rew_sum = args.gae_lambda * args.gamma * rew_sum + lam_sum * b_rew[t]
                    val_sum = args.gae_lambda * args.gamma * val_sum + args.gamma * nv
                    adv[t] = (rew_sum + val_sum) / lam_sum - b_val[t]
                else:
                    delta = b_rew[t] + args.gamma * nv - b_val[t]
                    last = delta + args.gamma * args.gae_lambda * cont * last
                    adv[t] = last
                adv[t] *= b_valid[t]
            returns = adv + b_val
        t1 = clock()
        gae_time += t1 - t0
        # -- update -------------------------------------------------------------------------
        keep = b_valid.reshape(-1) > 0
        f_obs = norm(b_obs.reshape(-1, obs_dim))[keep]
        f_act, f_logp = b_act.reshape(-1, act_dim)[keep], b_logp.reshape(-1)[keep]
        f_adv, f_ret = adv.reshape(-1)[keep], returns.reshape(-1)[keep]
        n = f_obs.shape[0]
        mb = max(1, min(minibatch, n))
        stop = False
        for _ in range(args.update_epochs):
            perm = torch.randperm(n).to(dev)  # drawn on the CPU: the same order on any device
            for s in range(0, n, mb):
                idx = perm[s:s + mb]
                if len(idx) < 2:
                    # The masked autoreset steps make the sample count vary, so the last
                    # minibatch can hold a single sample, whose advantage has no standard
                    # deviation (NaN). Skipped; larger remainders are used as before.
                    continue
                mean = actor(f_obs[idx])
                dist = Normal(mean, logstd.exp().expand_as(mean))
                logratio = dist.log_prob(f_act[idx]).sum(1) - f_logp[idx]
                ratio = logratio.exp()
                with torch.no_grad():
                    approx_kl = ((ratio - 1) - logratio).mean()
                if args.target_kl is not None and approx_kl > args.target_kl:
                    stop = True
                    break
                a = f_adv[idx]
                a = (a - a.mean()) / (a.std() + 1e-8)
                pg = torch.max(-a * ratio,
                               -a * torch.clamp(ratio, 1 - args.clip_coef, 1 + args.clip_coef)).mean()
                v_loss = 0.5 * ((critic(f_obs[idx]).view(-1) - f_ret[idx]) ** 2).mean()
                ent = dist.entropy().sum(1).mean()
                loss = pg - args.ent_coef * ent + args.vf_coef * v_loss
                w = bc_weight(global_step)
                if demos is not None and global_step <= args.critic_warmup_steps:
                    loss, w = args.vf_coef * v_loss, 0.0
                if w > 0:
                    j = torch.randint(len(demo_obs), (len(idx),))
                    bc = ((actor(norm(demo_obs[j.numpy()])) - demo_act[j.to(dev)]) ** 2).mean()
                    loss = loss + w * bc
                opt.zero_grad()
                loss.backward()
                nn.utils.clip_grad_norm_(params, args.max_grad_norm)
                opt.step()
            if stop:
                break
        update_time += clock() - t1
        learner_time = infer_time + gae_time + update_time
        wall = clock() - t_start
        ts = float(np.mean(ended_success)) if ended_success else ""
        tr = float(np.mean(ended_return)) if ended_return else ""
        append_row(log, writer, [
            it, global_step, f"{wall:.3f}", f"{sim_time:.3f}", f"{learner_time:.3f}", ts, tr,
            "", "", f"{infer_time:.3f}", f"{gae_time:.3f}", f"{update_time:.3f}",
            f"{eval_time:.3f}"])
        print(f"it {it}/{iterations} steps {global_step} wall {wall:.0f}s "
              f"(sim {sim_time:.0f}s, infer {infer_time:.0f}s, gae {gae_time:.0f}s, "
              f"update {update_time:.0f}s, eval {eval_time:.0f}s) "
              f"{global_step / wall:.0f} steps/s train success "
              f"{ts if ts == '' else round(ts, 3)}", flush=True)
        next_it = it + 1
        if args.max_minutes is not None and wall > 60 * args.max_minutes:
            break
        if stopping:
            break
    t0 = clock()
    eval_s, eval_r = evaluate()
    eval_time += clock() - t0
    append_row(log, writer, [
        it, global_step, f"{clock() - t_start:.3f}", f"{sim_time:.3f}",
        f"{infer_time + gae_time + update_time:.3f}", "", "", eval_s, eval_r,
        f"{infer_time:.3f}", f"{gae_time:.3f}", f"{update_time:.3f}", f"{eval_time:.3f}"])
    log.close()
    path = save("policy", eval_s)
    if best is None or eval_s >= best:
        best = eval_s
        save("best", eval_s)
    checkpoint(next_it)
    print(f"final eval success {eval_s:.3f} return {eval_r:.2f}; policy: {path}")
    print(f"  mjskill eval --policy {path}")


if __name__ == "__main__":
    main()

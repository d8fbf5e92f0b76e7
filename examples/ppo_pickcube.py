"""PPO on mjskill/PickCube-v1 (state obs) with the native vector env, CleanRL style.

A single-file PPO after CleanRL's ``ppo_continuous_action.py`` with ManiSkill's PPO baseline
settings for PickCube (gamma 0.8, GAE lambda 0.9, 50-step rollouts, 3×256 tanh MLPs,
state-independent log-std starting at -0.5, normalized dense reward), written in JAX + optax
(CPU) rather than PyTorch: PyTorch's CPU wheel index is not reachable from this project's
machines and PyPI's Linux torch wheel pulls in gigabytes of CUDA libraries.

The native vector env autoresets on the next step (gymnasium's next-step mode): the step after
an episode ended resets that env and ignores its action, so those transitions are masked out
of the loss and cut the GAE chain. Truncated episodes bootstrap from the value of their final
observation; terminated ones (success) do not.

Logs one JSON line per evaluation to stdout: env steps, wall time, success rate of a
deterministic evaluation (mean action) on fixed seeds, and the training episodes' success
rate and return since the last log.

    pip install mjskill 'jax[cpu]' optax
    python examples/ppo_pickcube.py --total-steps 3000000 --num-envs 32 --num-threads 2
"""

from __future__ import annotations

import argparse
import json
import time

import gymnasium as gym
import jax
import jax.numpy as jnp
import numpy as np
import optax

import mjskill  # noqa: F401  (registers the envs)


def parse_args():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--env-id", default="mjskill/PickCube-v1")
    p.add_argument("--robot-uids", default="panda")
    p.add_argument("--control-mode", default="pd_joint_delta_pos")
    p.add_argument("--total-steps", type=int, default=3_000_000)
    p.add_argument("--max-minutes", type=float, default=30.0, help="stop after this wall time")
    p.add_argument("--num-envs", type=int, default=32)
    p.add_argument("--num-threads", type=int, default=2)
    p.add_argument("--num-steps", type=int, default=50, help="rollout length per iteration")
    p.add_argument("--lr", type=float, default=3e-4)
    p.add_argument("--gamma", type=float, default=0.8)
    p.add_argument("--gae-lambda", type=float, default=0.9)
    p.add_argument("--update-epochs", type=int, default=4)
    p.add_argument("--num-minibatches", type=int, default=8)
    p.add_argument("--clip-coef", type=float, default=0.2)
    p.add_argument("--vf-coef", type=float, default=0.5)
    p.add_argument("--ent-coef", type=float, default=0.0)
    p.add_argument("--max-grad-norm", type=float, default=0.5)
    p.add_argument("--target-kl", type=float, default=0.1)
    p.add_argument("--eval-every", type=int, default=10, help="iterations between evaluations")
    p.add_argument("--eval-envs", type=int, default=32)
    p.add_argument("--seed", type=int, default=1)
    return p.parse_args()


def init_mlp(key, sizes, last_scale):
    params = []
    for i, (m, n) in enumerate(zip(sizes[:-1], sizes[1:])):
        key, k = jax.random.split(key)
        scale = last_scale if i == len(sizes) - 2 else np.sqrt(2)
        w = jax.nn.initializers.orthogonal(scale)(k, (m, n), jnp.float32)
        params.append((w, jnp.zeros(n, jnp.float32)))
    return params


def mlp(params, x):
    for w, b in params[:-1]:
        x = jnp.tanh(x @ w + b)
    w, b = params[-1]
    return x @ w + b


def log_prob(mean, logstd, a):
    return jnp.sum(
        -0.5 * ((a - mean) / jnp.exp(logstd)) ** 2 - logstd - 0.5 * jnp.log(2 * jnp.pi), -1
    )


@jax.jit
def act(params, obs, key):
    mean = mlp(params["actor"], obs)
    std = jnp.exp(params["logstd"])
    a = mean + std * jax.random.normal(key, mean.shape)
    return a, log_prob(mean, params["logstd"], a), mlp(params["critic"], obs)[:, 0]


@jax.jit
def act_mean(params, obs):
    return mlp(params["actor"], obs)


@jax.jit
def value(params, obs):
    return mlp(params["critic"], obs)[:, 0]


def make_update(opt, clip, vf_coef, ent_coef):
    def loss_fn(params, b):
        mean = mlp(params["actor"], b["obs"])
        newlogp = log_prob(mean, params["logstd"], b["act"])
        ratio = jnp.exp(newlogp - b["logp"])
        m = b["mask"]
        n = jnp.maximum(m.sum(), 1.0)
        adv = b["adv"]
        adv_mean = (adv * m).sum() / n
        adv_std = jnp.sqrt((((adv - adv_mean) * m) ** 2).sum() / n) + 1e-8
        adv = (adv - adv_mean) / adv_std
        pg = jnp.maximum(-adv * ratio, -adv * jnp.clip(ratio, 1 - clip, 1 + clip))
        v = mlp(params["critic"], b["obs"])[:, 0]
        vloss = 0.5 * (v - b["ret"]) ** 2
        ent = jnp.sum(params["logstd"] + 0.5 * jnp.log(2 * jnp.pi * jnp.e))
        loss = ((pg + vf_coef * vloss) * m).sum() / n - ent_coef * ent
        approx_kl = ((((ratio - 1) - jnp.log(ratio)) * m).sum()) / n
        return loss, approx_kl

    @jax.jit
    def update(params, opt_state, batch):
        (loss, kl), grads = jax.value_and_grad(loss_fn, has_aux=True)(params, batch)
        updates, opt_state = opt.update(grads, opt_state, params)
        return optax.apply_updates(params, updates), opt_state, loss, kl

    return update


def evaluate(params, env, seed):
    """Success rate of the mean action over one episode per env (seeds seed..seed+N-1)."""
    obs, _ = env.reset(seed=seed)
    done = np.zeros(env.num_envs, bool)
    success = np.zeros(env.num_envs, bool)
    while not done.all():
        a = np.asarray(act_mean(params, obs), np.float32)
        obs, _, term, trunc, _ = env.step(np.clip(a, -1, 1))
        success |= term & ~done
        done |= term | trunc
    return float(success.mean())


def main():
    args = parse_args()
    kw = dict(
        robot_uids=args.robot_uids,
        control_mode=args.control_mode,
        obs_mode="state",
        reward_mode="normalized_dense",
        vectorization_mode="vector_entry_point",
    )
    envs = gym.make_vec(args.env_id, num_envs=args.num_envs, num_threads=args.num_threads, **kw)
    eval_envs = gym.make_vec(args.env_id, num_envs=args.eval_envs, num_threads=1, **kw)
    obs_dim = envs.single_observation_space.shape[0]
    act_dim = envs.single_action_space.shape[0]
    key = jax.random.PRNGKey(args.seed)
    key, ka, kc = jax.random.split(key, 3)
    params = {
        "actor": init_mlp(ka, [obs_dim, 256, 256, 256, act_dim], 0.01 * np.sqrt(2)),
        "critic": init_mlp(kc, [obs_dim, 256, 256, 256, 1], 1.0),
        "logstd": jnp.full(act_dim, -0.5, jnp.float32),
    }
    opt = optax.chain(
        optax.clip_by_global_norm(args.max_grad_norm), optax.adam(args.lr, eps=1e-5)
    )
    opt_state = opt.init(params)
    update = make_update(opt, args.clip_coef, args.vf_coef, args.ent_coef)

    T, N = args.num_steps, args.num_envs
    buf_obs = np.zeros((T, N, obs_dim), np.float32)
    buf_act = np.zeros((T, N, act_dim), np.float32)
    buf_logp = np.zeros((T, N), np.float32)
    buf_val = np.zeros((T, N), np.float32)
    buf_rew = np.zeros((T, N), np.float32)
    buf_term = np.zeros((T, N), bool)
    buf_done = np.zeros((T, N), bool)
    buf_valid = np.zeros((T, N), bool)
    buf_final_val = np.zeros((T, N), np.float32)

    obs, _ = envs.reset(seed=args.seed * 1_000_000)
    autoreset = np.zeros(N, bool)  # envs whose next step is an autoreset
    t0 = time.time()
    global_step, it = 0, 0
    ep_ret = np.zeros(N)
    window = {"episodes": 0, "successes": 0, "return": 0.0}
    print(json.dumps({"event": "start", **vars(args)}), flush=True)
    while global_step < args.total_steps and time.time() - t0 < 60 * args.max_minutes:
        for t in range(T):
            key, k = jax.random.split(key)
            a, logp, v = act(params, obs, k)
            a = np.asarray(a, np.float32)
            buf_obs[t], buf_act[t] = obs, a
            buf_logp[t], buf_val[t] = np.asarray(logp), np.asarray(v)
            buf_valid[t] = ~autoreset
            obs, r, term, trunc, _ = envs.step(np.clip(a, -1, 1))
            global_step += N
            done = term | trunc
            buf_rew[t], buf_term[t], buf_done[t] = r, term, done
            # Final observations are the ones returned with the flags (next-step autoreset).
            buf_final_val[t] = np.asarray(value(params, obs)) if done.any() else 0.0
            ep_ret += np.where(autoreset, 0.0, r)
            for i in np.flatnonzero(done & ~autoreset):
                window["episodes"] += 1
                window["successes"] += int(term[i])
                window["return"] += ep_ret[i]
                ep_ret[i] = 0.0
            autoreset = done & ~autoreset
        # GAE over valid transitions; a transition's successor value is that of the obs its
        # step returned (the final obs when it ended).
        next_val = np.asarray(value(params, obs))
        adv = np.zeros((T, N), np.float32)
        last = np.zeros(N, np.float32)
        for t in reversed(range(T)):
            nv = next_val if t == T - 1 else buf_val[t + 1]
            nv = np.where(buf_done[t], buf_final_val[t], nv)
            delta = buf_rew[t] + args.gamma * nv * (~buf_term[t]) - buf_val[t]
            last = delta + args.gamma * args.gae_lambda * (~buf_done[t]) * last
            last = np.where(buf_valid[t], last, 0.0)
            adv[t] = last
        ret = adv + buf_val
        flat = {
            "obs": buf_obs.reshape(T * N, obs_dim),
            "act": buf_act.reshape(T * N, act_dim),
            "logp": buf_logp.reshape(-1),
            "adv": adv.reshape(-1),
            "ret": ret.reshape(-1),
            "mask": buf_valid.reshape(-1).astype(np.float32),
        }
        mb = T * N // args.num_minibatches
        rng = np.random.default_rng(args.seed + it)
        for _ in range(args.update_epochs):
            perm = rng.permutation(T * N)
            kls = []
            for s in range(0, T * N, mb):
                idx = perm[s : s + mb]
                params, opt_state, _, kl = update(
                    params, opt_state, {k: v[idx] for k, v in flat.items()}
                )
                kls.append(float(kl))
            if np.mean(kls) > args.target_kl:
                break
        it += 1
        if it % args.eval_every == 0:
            sr = evaluate(params, eval_envs, seed=10_000)
            w = window
            print(
                json.dumps(
                    {
                        "env_steps": global_step,
                        "wall_s": round(time.time() - t0, 1),
                        "eval_success_rate": sr,
                        "train_episodes": w["episodes"],
                        "train_success_rate": w["successes"] / max(w["episodes"], 1),
                        "train_mean_return": w["return"] / max(w["episodes"], 1),
                        "steps_per_s": round(global_step / (time.time() - t0)),
                    }
                ),
                flush=True,
            )
            window = {"episodes": 0, "successes": 0, "return": 0.0}


if __name__ == "__main__":
    main()

"""DynamicsNet training with every tensor on one torch device (``grip policy train --backend
warp``): the rollout buffer, the observation and return normaliser and the AMP discriminator as
device tensors (:mod:`policies.warp.rollout`, :mod:`policies.warp.amp`), and the trainer that
runs stable-baselines3's PPO update on them (:mod:`policies.warp.train`).

Like :mod:`policies.train`, nothing here imports an environment: the trainer receives a
constructor of a batched tensor env (``envs.warp.factory.make_warp_tracking_env`` at the edge).
"""

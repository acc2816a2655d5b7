"""Act and learn: goal-conditioned SAC, the trajectory replay buffer with HER relabelling,
and Skew-Fit's log p(x) estimate and skewed sampling.

    sac      networks, losses and one update (Haarnoja et al., rlkit's settings)
    replay   the buffer of whole trajectories with cached latents; HER batches
    skewfit  log p(x) of stored frames, p(x)^alpha weights, the inverse-CDF sampler
    her      fresh goals (ROLL's prior bank, the oracle's, Skew-Fit's skewed buffer) and the
             SAC updates on HER batches that relabel with them
"""

from roll_jax.common.lazy import lazy_api

__all__, __getattr__, __dir__ = lazy_api(__name__, {
    ".sac": ("SACState", "Transition", "init_sac", "sac_update", "select_action"),
    ".replay": ("ReplayBuffer", "Trajectory", "init_buffer", "add_trajectories",
                "sample_transitions", "sample_trajectories"),
    ".skewfit": ("frame_log_p", "skew_cdf", "skew_cdf_at", "sample_frames"),
    ".her": ("FreshGoals", "fresh_goals", "goal_prior", "sac_steps"),
})

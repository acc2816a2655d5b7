"""SAC + hindsight-relabeling config (paper appendix, Table 4 "SAC training hyper-parameters").

Table 4 = `supptable:sac-parameters` in the paper source: "the same values as used in Skew-Fit",
whose SAC is rlkit's `SACTrainer`; values the table leaves out take rlkit's / Skew-Fit's defaults
and say so.
"""

from __future__ import annotations

import dataclasses
import math


@dataclasses.dataclass(frozen=True)
class SACConfig:
    # Networks.
    hidden: tuple[int, ...] = (400, 300)  # Skew-Fit/RIG qf_kwargs and policy_kwargs hidden_sizes
    log_std_min: float = -20.0  # rlkit TanhGaussianPolicy LOG_SIG_MIN
    log_std_max: float = 2.0  # rlkit TanhGaussianPolicy LOG_SIG_MAX
    # Updates.
    discount: float = 0.99  # Table 4
    tau: float = 1e-3  # Table 4 (soft target tau)
    target_update_period: int = 1  # Table 4
    policy_lr: float = 1e-3  # Table 4
    q_lr: float = 1e-3  # Table 4
    # Table 4 only says "automatic alpha tuning: True"; rlkit's SACTrainer builds the alpha
    # optimizer with lr=policy_lr, so we use that (1e-3), not the 3e-4 of other SAC codebases.
    alpha_lr: float = 1e-3
    init_log_alpha: float = 0.0  # rlkit: log_alpha = zeros(1), i.e. alpha starts at 1
    target_entropy: float | None = None  # None -> -action_dim (SAC paper heuristic, rlkit default)
    batch_size: int = 1024  # Table 4
    updates_per_step: int = 2  # Table 4 (# training batches per time step)
    reward_scale: float = 1.0  # Table 4
    # Replay.
    replay_size: int = 100_000  # Table 4 (transitions; trajectories = replay_size // horizon)
    learning_starts: int = 10_000  # not in Table 4: Skew-Fit's min_num_steps_before_training
    # Goal relabeling (RIG-style HER, Algorithm 1): Skew-Fit's relabeling buffer
    # (fraction_goals_rollout_goals=0.2, fraction_goals_env_goals=0.5 -> prior goals, rest future).
    rollout_goal_frac: float = 0.2
    prior_goal_frac: float = 0.5
    future_goal_frac: float = 0.3

    def __post_init__(self):
        if not self.hidden or any(int(h) <= 0 for h in self.hidden):
            raise ValueError(f"SACConfig.hidden must be non-empty positive sizes, got {self.hidden}")
        for name in ("target_update_period", "batch_size", "updates_per_step", "replay_size"):
            if getattr(self, name) <= 0:
                raise ValueError(f"SACConfig.{name} must be positive, got {getattr(self, name)}")
        for name in ("policy_lr", "q_lr", "alpha_lr", "reward_scale"):
            if not getattr(self, name) > 0:
                raise ValueError(f"SACConfig.{name} must be positive, got {getattr(self, name)}")
        if self.learning_starts < 0:
            raise ValueError(f"SACConfig.learning_starts must be >= 0, got {self.learning_starts}")
        if not 0.0 <= self.discount <= 1.0:
            raise ValueError(f"SACConfig.discount must be in [0, 1], got {self.discount}")
        if not 0.0 < self.tau <= 1.0:
            raise ValueError(f"SACConfig.tau must be in (0, 1], got {self.tau}")
        if not self.log_std_min < self.log_std_max:
            raise ValueError(
                f"SACConfig.log_std_min must be < log_std_max, got {self.log_std_min} >= {self.log_std_max}")
        for name in ("rollout_goal_frac", "prior_goal_frac", "future_goal_frac"):
            if not 0.0 <= getattr(self, name) <= 1.0:
                raise ValueError(f"SACConfig.{name} must be in [0, 1], got {getattr(self, name)}")
        total = sum(self.goal_fracs)
        if not math.isclose(total, 1.0, abs_tol=1e-6):
            raise ValueError(f"SACConfig goal fractions (rollout, prior, future) must sum to 1, got "
                             f"{self.goal_fracs} (sum {total})")

    @property
    def goal_fracs(self) -> tuple[float, float, float]:
        """(rollout, prior, future) relabeling fractions, the order `replay.sample_transitions` takes."""
        return (self.rollout_goal_frac, self.prior_goal_frac, self.future_goal_frac)

    def replay_capacity(self, horizon: int) -> int:
        """Replay capacity in trajectories (the buffer stores whole episodes of `horizon` steps)."""
        if horizon <= 0:
            raise ValueError(f"horizon must be positive, got {horizon}")
        return max(1, self.replay_size // horizon)

    def entropy_target(self, action_dim: int) -> float:
        """Target entropy of the automatic alpha tuning: `target_entropy`, or -action_dim."""
        return float(-action_dim) if self.target_entropy is None else float(self.target_entropy)


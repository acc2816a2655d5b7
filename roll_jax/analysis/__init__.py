"""Measure it: a run's policy on goal images, the paper's representation analyses and
comparisons of runs (`roll-analysis CMD`, `roll-evaluate`).

    evaluation / evaluate  a run's policy on given or sampled goal images (roll-evaluate)
    stats                  rank correlations, position fits, paired differences
    checkpoints            a pretraining directory's config and encoders as callables
    fig5                   latent vs object distance (paper Figure 5)
    occlusion              occluded-frame retrieval (appendix A)
    reward_probe           what runs' reward encoders measure: object vs hand distance
    diagnose               a push task's encoders, reset and prior goals
    compare                two runs paired; the policy panel
"""

from roll_jax.common.lazy import lazy_api

__all__, __getattr__, __dir__ = lazy_api(__name__, {
    # (the evaluation function is `evaluation.evaluate`: `evaluate` names the command's module)
    ".evaluation": ("load_run", "write_outputs"),
    ".stats": ("spearman", "pearson", "position_r2", "pairwise_spearman"),
    ".checkpoints": ("load_checkpoint", "model_encoders"),
    ".fig5": ("observation_set", "latent_vs_distance", "run_latent_vs_distance"),
    ".occlusion": ("occlusion_retrieval", "run_occlusion"),
    ".compare": ("compare",),
})

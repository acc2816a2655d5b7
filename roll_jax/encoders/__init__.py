"""Encode: the scene-VAE (the policy's observation), the object-VAE and the LSTM (goals and
rewards), how a run turns images into those latents, and their pretraining.

    models         the networks (conv beta-VAE, LSTM) and how a config's model is applied
    losses         beta-VAE, VAE matching and LSTM auto-encoder + matching losses
    steps          train states and pure train steps / epochs of the VAEs and the LSTM
    goal_encoding  GoalEncoder: images -> observation, goal and achieved latents per algorithm
    oracle         StateOracle: the same contract with true positions for latents
    pretrain       datasets, pretraining, encoder checkpoints (`python -m ...pretrain`)
"""

from roll_jax.common.lazy import lazy_api

__all__, __getattr__, __dir__ = lazy_api(__name__, {
    ".models": ("ConvVAE", "LSTMEncoder", "lstm_encode", "encode_mean", "decode", "vae_model",
                "lstm_model"),
    ".steps": ("ModelState", "init_vae", "init_lstm", "vae_train_step", "lstm_train_step",
               "vae_fit_epoch", "lstm_fit_epoch", "make_occlusion", "OcclusionSource"),
    ".goal_encoding": ("Frozen", "GoalEncoder", "goal_encoder"),
    ".oracle": ("StateOracle",),
    ".pretrain": ("Pretrained", "pretrain", "save", "load", "initial",
                  "fit_or_load_segmentation"),
})

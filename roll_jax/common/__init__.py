"""What every layer of roll_jax uses and nothing of roll_jax is imported by: convolutions as
matmuls (the U-Net's and the VAEs'), checkpoint folders (a meta.json beside the orbax
pytrees; a run's train states), the packages' lazy exports."""

from roll_jax.common.lazy import lazy_api

__all__, __getattr__, __dir__ = lazy_api(__name__, {
    ".conv": ("Conv", "ConvTranspose"),
    ".checkpoint": ("read_meta", "write_meta", "train_state_manager", "save_train_state",
                    "restore_train_state"),
})

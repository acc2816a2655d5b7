"""door_open: the task's training values (Table 2; run length: the reference code)."""

TRAIN = {
    "horizon": 100,  # Table 2: trajectory length
    "total_env_steps": 250000,  # reference code launch files: epochs x 500 env steps
    "skew_alpha": -0.5,  # Table 2: Skew-Fit alpha for the scene-VAE
    "vae_schedule": "custom_schedule",  # Skew-Fit appendix C.5 (rlkit vae_schedules)
    "n_envs": 5,  # ours: 5 envs x 100 steps = one 500-step epoch
    # reference code (launch_ROLL_sawyerdoor.py, door_original_dataset.npy): goal images
    "scene_pretrain_data": "goals",
}

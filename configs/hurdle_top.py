"""hurdle_top: the task's training values (Table 2; run length: the reference code)."""

TRAIN = {
    "horizon": 50,  # Table 2: trajectory length
    "total_env_steps": 400000,  # reference code launch files: epochs x 500 env steps
    "skew_alpha": -1.0,  # Table 2: Skew-Fit alpha for the scene-VAE
    "vae_schedule": "custom_schedule_2",  # Skew-Fit appendix C.5 (rlkit vae_schedules)
    # reference code (launch_ROLL_sawyerhurdle.py): puck and hand over the corridor
    "scene_pretrain_data": "region",
}

"""Typed per-task configs (one module per task, paper values tagged with their table): they
arrive with the encoder and training issues. Task geometry lives in envs_mjx/tasks.py."""

"""Typed configs: component dataclasses (segmentation, encoders, sac), the composed
`train.TrainConfig`, and one module per task with that task's values (Table 2)."""

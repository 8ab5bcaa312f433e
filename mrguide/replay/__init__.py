"""See what happened: run logs and recorded training episodes as Rerun recordings (`mrguide replay`), and a
training run's demonstrations as a LeRobot dataset (`mrguide export lerobot`). See docs/replay.md."""

"""mrguide: demonstration-augmented DDPG with mixed-reality guidance, a PyBullet twin and a CANopen deploy stack."""

__version__ = "0.2.0"

#: The twin's Gymnasium id: after `import mrguide`, `gymnasium.make(ENV_ID)` builds a `PickPlaceEnv` (default config;
#: `config=EnvConfig.load(path)` for another). Registered only where Gymnasium is installed (not on a robot PC);
#: the entry point is a string, so nothing of the twin is imported until an env is made.
ENV_ID = "mrguide/PickPlace-v0"
try:
    import gymnasium
except ImportError:  # a robot PC: no Gymnasium, nothing to register
    pass
else:
    gymnasium.register(id=ENV_ID, entry_point="mrguide.twin.env:PickPlaceEnv")

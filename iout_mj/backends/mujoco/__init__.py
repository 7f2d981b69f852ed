"""The MuJoCo backend: vehicle and scene (MJCF), physics with metered actuators, the dm_control
task, and offscreen rendering."""

"""The paper's equations in numpy (no MuJoCo): geometry, acoustics, sensor network, propulsion."""

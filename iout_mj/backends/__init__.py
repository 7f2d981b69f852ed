"""How vehicles move: the paper's kinematics (`kinematic`) and MuJoCo physics (`mujoco`)."""

"""The simulated world: one PyBullet scene per client, the rays, the arm's kinematics, rendering."""

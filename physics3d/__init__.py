"""The 3D tier (PyBullet warehouse): built in a later milestone."""

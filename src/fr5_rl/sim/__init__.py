"""PyBullet layer: the world (client, table, object) and the arm in it."""

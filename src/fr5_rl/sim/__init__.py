"""PyBullet layer: the world (client, table, object) and the FR5 robot in it."""

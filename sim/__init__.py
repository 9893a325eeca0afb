"""Everything that touches PyBullet: client, world builder, UGV body, lasers, ground truth."""

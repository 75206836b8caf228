"""MuJoCo host simulator: the arm and its six emulated motor drives on a CAN bus."""

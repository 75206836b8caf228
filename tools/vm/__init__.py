"""The qemu TCG VM with a real vcan0: image set-up and cache (image.py, kmod.py), running a command in it (run.py)."""

"""The arm: a user's model (MJCF or URDF, optionally with an arm file) made into the one model
that the generator, the firmware, the simulator and the study all use.

`python -m gen.arm --model M [--arm-file F] --design CONFIG --out DIR [--depfile F]` writes into DIR:

- arm.xml: the prepared MJCF. The controlled joints are hinges of one serial chain, every other
  joint is locked (removed, its body fixed at the locked value), fixed bodies are fused into their
  link, every body's mass and inertia is explicit (geometry and meshes are dropped unless the arm
  file keeps contacts), the model's own actuators, sensors, tendons, equalities and keyframes are
  replaced by one motor per controlled joint (gear 1, ctrlrange = the torque limit) and a keyframe
  "home", and the timestep is the loop period (or an integer fraction of it).
- arm.json: what the rest of the project reads: the joints (limits, ranges, armature, damping,
  friction, home), the locked joints, the timestep and substeps, the bus wiring, the default
  reference, the policies and every warning, and the model hash (FNV-1a 64 of arm.xml).
- design.toml: the design config with the model's joint count.
- plant.xml: the simulator's true arm with flexible joints (gen/drivetrain.py: per joint a rotor,
  the strain-wave gear's spring and damper, the link); arm.json holds each joint's drive train, the
  first resonance and the rated payload, and arm.xml a site "payload" at the flange.

prepare() (preparation.py) is one call per stage, each a module: load, compile, chain, home, the
dynamics-only model and the torque limits, write, reference, design, drive train. Errors name the element and
say what to change (exit 2); nothing is written then.
"""

# Each name is imported from its module when first asked for (PEP 562): `python -m gen.arm` in a
# build that finds its arm prepared already (gen/arm/cli.py) reads a key file, not MuJoCo.
_FROM = {
    "gen.arm.arm_file": ("ARM_FILE_FIELDS", "DEFAULT_DESIGN", "DEFAULT_MODEL", "ArmFile", "arm_name", "arm_name_of",
                         "load_arm_file"),
    "gen.arm.cli": ("main",),
    "gen.arm.design": ("AUTO_WN_MAX", "AUTO_WN_MIN", "auto_bandwidth", "design_for",
                       "with_static_controller"),
    "gen.arm.errors": ("ArmError",),
    "gen.arm.preparation": ("Prepared", "prepare"),
    "gen.arm.reference": ("RANGE_MARGIN", "REF_MAX_ACCELERATION", "REF_MAX_VELOCITY", "REF_TORQUE_FRACTION",
                          "clip_amplitude", "default_reference", "fit_reference", "reference_peak_fraction",
                          "reference_rule", "reference_torque"),
    "gen.arm.wiring": ("BUS_BUDGET", "DEFAULT_TOPOLOGY"),
    "gen.arm.write": ("inverse_dynamics_difference", "inverse_forces"),
    "gen.lib.model_hash": ("fnv1a64",),
}
_MODULE_OF = {name: module for module, names in _FROM.items() for name in names}
__all__ = sorted(_MODULE_OF)


def __getattr__(name: str) -> object:
    import importlib

    if name not in _MODULE_OF:
        raise AttributeError(f"module 'gen.arm' has no attribute '{name}'")
    value = getattr(importlib.import_module(_MODULE_OF[name]), name)
    globals()[name] = value
    return value

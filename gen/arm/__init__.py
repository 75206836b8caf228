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

prepare() (prepare.py) is one call per stage, each a module: load, compile, chain, home, the
dynamics-only model and the torque limits, write, reference, design, drive train. Errors name the element and
say what to change (exit 2); nothing is written then.
"""

from gen.arm.arm_file import ARM_FILE_FIELDS, DEFAULT_MODEL, ArmFile, arm_name, arm_name_of, load_arm_file
from gen.arm.design import (AUTO_WN_MAX, AUTO_WN_MIN, DEFAULT_DESIGN, auto_bandwidth, design_for,
                            with_static_controller)
from gen.arm.errors import ArmError
from gen.arm.prepare import Prepared, prepare
from gen.arm.reference import (RANGE_MARGIN, REF_MAX_ACCELERATION, REF_MAX_VELOCITY, REF_TORQUE_FRACTION,
                               clip_amplitude, default_reference, fit_reference, reference_peak_fraction,
                               reference_rule, reference_torque)
from gen.arm.wiring import BUS_BUDGET, DEFAULT_TOPOLOGY
from gen.arm.write import inverse_dynamics_difference, inverse_forces
from gen.lib.model_hash import fnv1a64

__all__ = ["ARM_FILE_FIELDS", "AUTO_WN_MAX", "AUTO_WN_MIN", "BUS_BUDGET", "DEFAULT_DESIGN", "DEFAULT_MODEL",
           "DEFAULT_TOPOLOGY", "RANGE_MARGIN", "REF_MAX_ACCELERATION", "REF_MAX_VELOCITY", "REF_TORQUE_FRACTION",
           "ArmError", "ArmFile", "Prepared", "arm_name", "arm_name_of", "auto_bandwidth", "clip_amplitude",
           "default_reference", "design_for", "fit_reference", "fnv1a64", "inverse_dynamics_difference",
           "inverse_forces", "load_arm_file", "prepare", "reference_peak_fraction", "reference_rule",
           "reference_torque", "with_static_controller"]

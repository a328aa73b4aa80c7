"""Stage 1, simulation: the MuJoCo ring (model), its sweeps (sim), the effects that turn true
ranges into ADC counts (effects, rangers) and the physics-stepped ones (dynamics)."""

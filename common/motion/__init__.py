"""Moving obstacles: their motion in a scenario (:mod:`common.motion.spec`) and the code that moves
them, once for every tier (:class:`common.motion.movers.Movers`)."""

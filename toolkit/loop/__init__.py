"""The closed loop at the sample rate: the exact plant, the sensor law, an estimator and a
controller (:mod:`~toolkit.loop.closed_loop`), and the same loop as python-control systems
(:mod:`~toolkit.loop.interop`)."""

"""The closed loop at the sample rate: the exact plant, the sensor law, an estimator and a
controller (:mod:`~toolkit.loop.closed_loop`), the same loop as python-control systems
(:mod:`~toolkit.loop.interop`), and its independent check against the plant's smoothed
model in python-control (:mod:`~toolkit.loop.cross_check`)."""

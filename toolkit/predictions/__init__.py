"""The paper's predictions: what the ideal model says (:mod:`.theory`) and the closed-loop checks."""

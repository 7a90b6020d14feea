"""island: the thesis' GA and PSO as ask/tell optimizers, local polish, and the Zenoh island node."""

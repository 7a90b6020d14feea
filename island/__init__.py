"""island: the thesis' GA and PSO as ask/tell optimizers, their termination and polish, and the island
node that migrates over Zenoh (with the campaign's wire format and configuration)."""

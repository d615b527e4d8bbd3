"""The finger's discretisations (CCM, PCC, arc, rod): their unknowns and the engine's hooks."""

"""Pressure-regulator backends behind one Protocol."""

"""The laminate's cross-section: its materials, its section law and a finger's segments."""

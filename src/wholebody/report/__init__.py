"""Figures and tables of scenario results."""

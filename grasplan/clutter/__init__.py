"""Clutter removal in physics (issue 21): drop a pile, pick until the bin is empty, measure GSR and DR."""

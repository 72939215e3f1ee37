"""Clutter removal in physics: drop a pile, pick until the bin is empty, measure grasp success (GSR) and declutter (DR) rates."""

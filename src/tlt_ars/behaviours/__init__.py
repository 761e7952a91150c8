"""Leaf behaviours of the ARS tree: end effector, vision requests, parts and inspection."""

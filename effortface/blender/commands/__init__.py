"""The Blender room's command: ``effortface blender-addon``."""

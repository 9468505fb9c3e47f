"""The bpy layer of grlens (imports bpy)."""

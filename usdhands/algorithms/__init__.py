"""Algorithms on arrays: DTW, segmentation, synthesis, splicing, reduction, interaction.

Never imports ``pxr`` or ``pygltflib``.
"""

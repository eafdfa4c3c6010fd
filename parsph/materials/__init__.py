"""Constitutive laws: stress and strain-energy density from the deformation gradient."""

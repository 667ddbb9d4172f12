"""The planar example of the design notes as case-file text (outer_passes 4), for the case
loader and the input-validation tests."""

from __future__ import annotations

PLANAR = """\
name: planar
kinematics: small                  # small | finite
steps: 1                           # load steps; displacement values are reached linearly
bodies:
  lower:                           # body names are free
    geometry: {builder: box, min: [0, 0, 0], max: [0.0025, 0.01, 0.01]}
    material: {model: linear_elastic, E: 115.0e9, nu: 0.3}   # or neo_hookean
    grid: {h0: 0.0025, offset: [0.13, 0.29, 0.41]}           # h = h0 / 2**level
  upper:
    geometry: {builder: box, min: [0, 0, 0.01], max: [0.0025, 0.01, 0.02]}
    material: {model: linear_elastic, E: 115.0e9, nu: 0.3}
    grid: {h0: 0.0025, offset: [0.37, 0.71, 0.23]}
boundary:                          # patches by name; components not named stay free
  - {body: upper, patches: [zmax], type: displacement, components: {y: 0.0, z: -1.6e-6}}
  - {body: lower, patches: [zmin], type: displacement, components: {y: 0.0}}
  - {body: lower, patches: [xmin, xmax], type: displacement, components: {x: 0.0}}
  - {body: upper, patches: [xmin, xmax], type: displacement, components: {x: 0.0}}
  - {body: lower, patches: [ymin], type: traction, value: ["0", "4e11*(0.01-z)*z", "10e11*(0.01-z)*z"]}
  - {body: lower, patches: [ymax], type: traction, value: ["0", "-4e11*(0.01-z)*z", "10e11*(0.01-z)*z"]}
contact:
  - {slave: lower, master: upper, kappa: 10.0}   # penalty kE/h with E of the slave body
solver: {newton_tol: 1.0e-9, max_newton: 30, outer_passes: 4, linear: auto}
"""

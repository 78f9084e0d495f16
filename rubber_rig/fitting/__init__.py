"""Identification of rubber-element parameters from recordings (pure Python, no rclpy).

blocks      split a recording into blocks, skip settling cycles, measure K_dyn, loss angle, D, energy, C_eq
properties  seed-000 model properties evaluated as the rig measures them (first harmonic, loop area)
identify    seed 000 Eq. 29 by differential evolution + least-squares polish, uncertainty from the Jacobian
"""

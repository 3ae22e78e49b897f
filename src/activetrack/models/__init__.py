"""The models a scenario composes: target motion (eq. 1-3, 39), sensor measurement
models (eq. 4-10), the covariance objective (eq. 12, 17-19) and the occluders.
"""

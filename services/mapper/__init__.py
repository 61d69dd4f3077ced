"""The mapper: one EKF per wall, served as a Zenoh queryable."""

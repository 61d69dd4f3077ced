"""The wallmap services: player, detector and mapper, each a thin shell around common/."""

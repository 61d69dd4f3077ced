"""The maths and plumbing the services share: pure numpy, no Zenoh except in transport."""

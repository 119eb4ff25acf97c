"""The drone link: MAVSDK connections, verified uploads with read-back, and fleet uploads."""

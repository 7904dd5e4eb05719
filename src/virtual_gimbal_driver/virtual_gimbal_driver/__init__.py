"""The reference driver: an invented pan-tilt device laid out like every real driver."""

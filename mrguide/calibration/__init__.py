"""Marker calibration: ArUco detection, marker/board pose, registration of the HMD frame to the robot base,
calibration files, and object pose sources through the calibration. numpy + OpenCV only (no PyBullet, no
torch): deploy code imports it. The twin side (textured markers, the simulated HMD) is `mrguide.twin.markers`.
"""

"""Pure numerical core of the console: robot descriptions, kinematics, planning and control.

Nothing under ``core`` imports viser, pyserial, sockets or threads.
"""

"""The CANopen objects mrguide reads and writes, named once: CiA 301's communication objects, CiA 402's drive
objects and the vacuum generator's manufacturer objects (a COVAL LEMCOM island's layout). The master, the simulated
devices, the boot checks, the EDS check and the bus monitor all use these names, so they cannot agree on a typo
that a test on the simulated bus would not see; `tests/drivers/test_objects.py` checks every name against the
shipped EDS files."""

# -- CiA 301 ----------------------------------------------------------------------------------------------
DEVICE_TYPE = 0x1000
ERROR_REGISTER = 0x1001
CONSUMER_HEARTBEAT_TIME = 0x1016
PRODUCER_HEARTBEAT_TIME = 0x1017
RPDO_COMMUNICATION, RPDO_MAPPING = 0x1400, 0x1600  # of RPDO1; RPDOn at + n - 1
TPDO_COMMUNICATION, TPDO_MAPPING = 0x1800, 0x1A00  # of TPDO1

# -- CiA 402 (a drive) ------------------------------------------------------------------------------------
ERROR_CODE = 0x603F
CONTROLWORD = 0x6040
STATUSWORD = 0x6041
QUICK_STOP_OPTION_CODE = 0x605A
MODES_OF_OPERATION = 0x6060
MODES_OF_OPERATION_DISPLAY = 0x6061
POSITION_ACTUAL_VALUE = 0x6064
FOLLOWING_ERROR_WINDOW = 0x6065
FOLLOWING_ERROR_TIME_OUT = 0x6066
VELOCITY_ACTUAL_VALUE = 0x606C
TARGET_POSITION = 0x607A
QUICK_STOP_DECELERATION = 0x6085
INTERPOLATION_TIME_PERIOD = 0x60C2  # sub 1: value, sub 2: index (value * 10**index s)
SUPPORTED_DRIVE_MODES = 0x6502

# -- the vacuum generator (manufacturer area) --------------------------------------------------------------
VACUUM_COMMAND = 0x2000
PART_GRIPPED = 0x2001
PART_LOST = 0x2003
VACUUM_LEVEL = 0x2020  # sub 1: module 0
GRIP_THRESHOLD = 0x2100
GRIP_HYSTERESIS = 0x2101

"""Simulated CANopen devices of the cobot on a python-can bus, fault injection."""

from mrguide.drivers.mock.first_order_plant import FirstOrderParams, FirstOrderPlant
from mrguide.drivers.mock.sim_cobot import SimulatedCobot

__all__ = ["FirstOrderParams", "FirstOrderPlant", "SimulatedCobot"]

"""What the buses on CAN (DeviceNet, CANopen) share, protocol-free, above the CAN medium
of :mod:`adapters.link`:

* :mod:`.frame`: the classic CAN data frame a bus's codec subclasses (its decode error);
* :mod:`.events`: the link events every engine on CAN steps and the frame it sends;
* :mod:`.health`: the line's health from its error frames' conditions;
* :mod:`.bits`: a data frame's length in bit times;
* :mod:`.adapter`: the CAN adapter base the DeviceNet and CANopen adapters fill in.
"""

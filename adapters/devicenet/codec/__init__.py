"""The DeviceNet codec layer (sans-IO, fact sheet Part 2): ``frame`` (the CAN frame),
``ids`` (identifiers, predefined connection set), ``explicit`` (explicit message bodies),
``fragment`` (fragmentation protocol), ``dupmac`` (Duplicate MAC ID check), ``cip``
(general status, services, classes), ``objects`` (class 1/3/5 numbers), ``datatypes``
(CIP elementary types), ``eds`` (EDS files), ``validate`` (the bytes check they share).
Typed decode errors are the package's ``errors``."""

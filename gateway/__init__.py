"""drive-gateway: Profibus DP, DeviceNet and CANopen drives on Zenoh and Modbus TCP."""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("drive-gateway")
except PackageNotFoundError:  # running from a source tree without install
    __version__ = "0.0.0+unknown"

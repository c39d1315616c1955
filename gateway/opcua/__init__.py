"""The OPC UA front end (asyncua): the drive model for SCADA systems that read OPC UA.

See gateway/opcua/frontend.py; the ``[opcua]`` table is read by gateway/opcuaconfig.py.
"""

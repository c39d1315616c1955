"""``make test-vcan``: the ``vcan`` tests in a Linux kernel that has SocketCAN.

On the host when it has (or, as root, can make) ``vcan0``; otherwise in a throwaway qemu
VM booting Debian's own kernel with the host's filesystem shared over 9p
(``python -m tests.vcan_vm``; docs/decisions/0028-vcan-suite-in-a-vm.md).
"""

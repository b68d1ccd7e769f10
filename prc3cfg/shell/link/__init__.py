"""The link: PRC 3 messages over a real line (device path, pyserial URL or `emulator://`).

`client` is the link itself (`Link`, its errors, `Exchange`, and `Port`: what it needs of a port);
`ports` opens a plant bus's line — a device, a URL, or an emulator in this process — and lists the
machine's serial ports; `trace` writes a frame trace. Import from the module that holds a name:
this package imports none of them, so what needs only one (a record of an exchange, a trace) loads
neither pyserial nor the emulator.
"""

"""The PRC 3 bus emulator: the device model served behind a real framing on a real stream.

`bus` is pure (who gets a message); `state` is the state file and, while an emulator
runs, the journal beside it; `server` is the running emulator over TCP and
pseudo-terminals, with the Python API tests use while it runs; `ptys` lists the
pseudo-terminals this user's emulators serve. Import from the module that holds a name: this
package imports none of them, so what needs only the state file loads no server.
"""

"""The ``design`` sub-commands' parsers and printers: parse, call the library, print."""

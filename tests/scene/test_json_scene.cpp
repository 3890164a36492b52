// placeholder: tests arrive with this module's implementation

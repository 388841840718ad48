//! Turntable firmware for QEMU's lm3s6965evb: the shared protocol logic
//! ([`turntable_proto::Device`]) served on UART0, with a SysTick time base and the commanded
//! position driven out as STEP/DIR pulses on GPIO port F (pins 0 and 1).
//!
//! The core sleeps in WFI with PRIMASK set: a pending UART0 or SysTick interrupt wakes it
//! without running a handler, so QEMU does not spin a host core.
#![no_std]
#![no_main]

use core::ptr::{read_volatile, write_volatile};
use cortex_m::peripheral::{syst::SystClkSource, NVIC, SCB, SYST};
use cortex_m_rt::entry;
use panic_halt as _;
use turntable_proto::{Config, Device, Sink};

const UART0: usize = 0x4000_C000;
const DR: usize = 0x000;
const FR: usize = 0x018; // bit 4 RXFE, bit 5 TXFF
const IM: usize = 0x038; // bit 4 RXIM, bit 6 RTIM
const ICR: usize = 0x044;
const UART0_IRQ: u16 = 5;
const GPIOF: usize = 0x4002_5000;
const GPIO_DIR: usize = 0x400;
const STEP_PIN: u32 = 1 << 0;
const DIR_PIN: u32 = 1 << 1;
/// SysTick ticks per millisecond. QEMU clocks the lm3s6965evb core at 12.5 MHz out of reset
/// (measured: with 12 000 the device clock ran 4.2 % fast against the host's).
const TICKS_PER_MS: u32 = 12_500;

fn reg(addr: usize) -> *mut u32 {
    addr as *mut u32
}

fn putc(b: u8) {
    // SAFETY: UART0 registers of the LM3S6965, accessed only from this single thread.
    unsafe {
        while read_volatile(reg(UART0 + FR)) & (1 << 5) != 0 {}
        write_volatile(reg(UART0 + DR), b as u32);
    }
}

fn getc() -> Option<u8> {
    // SAFETY: as in `putc`.
    unsafe {
        if read_volatile(reg(UART0 + FR)) & (1 << 4) != 0 {
            None
        } else {
            Some(read_volatile(reg(UART0 + DR)) as u8)
        }
    }
}

struct Uart;

impl Sink for Uart {
    fn send(&mut self, line: &str) {
        line.bytes().for_each(putc);
        putc(b'\n');
    }
}

/// Microsecond clock from the millisecond SysTick wrap count plus the current counter value.
struct Clock {
    syst: SYST,
    ms: u64,
}

impl Clock {
    fn now_us(&mut self) -> u64 {
        // The SysTick exception is never taken (PRIMASK=1), so clear its pending bit by hand.
        SCB::clear_pendst();
        if self.syst.has_wrapped() {
            self.ms += 1;
        }
        let elapsed = TICKS_PER_MS - 1 - SYST::get_current().min(TICKS_PER_MS - 1);
        self.ms * 1000 + (elapsed as u64 * 1000 / TICKS_PER_MS as u64)
    }
}

#[derive(Clone, Copy)]
struct Irq(u16);

// SAFETY: 5 is UART0's interrupt number on the LM3S6965.
unsafe impl cortex_m::interrupt::InterruptNumber for Irq {
    fn number(self) -> u16 {
        self.0
    }
}

/// Emits STEP pulses (with DIR) until the motor position reaches the commanded one.
struct Stepper {
    at: i64,
}

impl Stepper {
    fn follow(&mut self, target: i64) {
        while self.at != target {
            let dir = if target > self.at { 1 } else { -1 };
            // SAFETY: GPIO port F data register, bit-masked address for pins 0 and 1.
            unsafe {
                write_volatile(reg(GPIOF + ((STEP_PIN | DIR_PIN) as usize) * 4), if dir > 0 { DIR_PIN } else { 0 });
                write_volatile(
                    reg(GPIOF + ((STEP_PIN | DIR_PIN) as usize) * 4),
                    STEP_PIN | if dir > 0 { DIR_PIN } else { 0 },
                );
            }
            self.at += dir;
        }
    }
}

#[entry]
fn main() -> ! {
    let mut cp = cortex_m::Peripherals::take().expect("peripherals taken once");
    cortex_m::interrupt::disable();
    // SAFETY: enabling UART0 receive interrupts and GPIO F outputs during single-threaded init.
    unsafe {
        write_volatile(reg(UART0 + IM), (1 << 4) | (1 << 6));
        NVIC::unmask(Irq(UART0_IRQ));
        write_volatile(reg(GPIOF + GPIO_DIR), STEP_PIN | DIR_PIN);
    }
    cp.SYST.set_clock_source(SystClkSource::Core);
    cp.SYST.set_reload(TICKS_PER_MS - 1);
    cp.SYST.clear_current();
    cp.SYST.enable_interrupt();
    cp.SYST.enable_counter();
    let mut clock = Clock { syst: cp.SYST, ms: 0 };
    let mut dev = Device::new(Config { fw_version: "0.1.0-qemu", ..Config::default() }, 0);
    dev.reset(0, &mut Uart);
    let mut stepper = Stepper { at: 0 };
    loop {
        while let Some(b) = getc() {
            let now = clock.now_us();
            dev.feed(b, now, &mut Uart);
        }
        let now = clock.now_us();
        dev.poll(now, &mut Uart);
        stepper.follow(dev.physical_position(now));
        cortex_m::asm::wfi();
        // SAFETY: clearing UART0 interrupt flags; the interrupt is only used to wake WFI.
        unsafe { write_volatile(reg(UART0 + ICR), 0x7ff) };
        NVIC::unpend(Irq(UART0_IRQ));
    }
}
